"""Bounds every input shares: what the databases' integer columns hold."""

# Every id column is a 32-bit signed INTEGER in PostgreSQL; counters and bit caps are 64-bit.
INT32_MAX = 2**31 - 1
INT64_MAX = 2**63 - 1
