"""The audit trail: recording and viewing who did what."""
