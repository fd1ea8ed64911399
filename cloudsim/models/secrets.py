"""Secrets (SSH keys, VPN keys, cloud credentials), encrypted at rest."""

from __future__ import annotations

import enum
from datetime import datetime

from sqlalchemy import String, UniqueConstraint
from sqlalchemy.orm import Mapped, mapped_column

from cloudsim.crypto import EncryptedText
from cloudsim.models.base import Base, UTCDateTime, str_enum, utcnow


class SecretKind(enum.StrEnum):
    """What a secret is, which decides who may download it."""

    SSH_PRIVATE_KEY = "ssh_key"
    VPN_KEY = "vpn_key"
    CLOUD_CREDENTIALS = "cloud_creds"


class Secret(Base):
    """One encrypted value owned by a constellation, a team or the installation."""

    __tablename__ = "secrets"
    __table_args__ = (UniqueConstraint("owner_type", "owner_id", "name"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    kind: Mapped[SecretKind] = mapped_column(str_enum(SecretKind))
    owner_type: Mapped[str] = mapped_column(String(32))
    owner_id: Mapped[int] = mapped_column(default=0)  # 0 = the installation itself
    name: Mapped[str] = mapped_column(String(120))
    value: Mapped[str] = mapped_column(EncryptedText)
    created_at: Mapped[datetime] = mapped_column(UTCDateTime, default=utcnow)

    def __repr__(self) -> str:
        return (
            f"<Secret {self.id} {self.kind.value} {self.owner_type}:{self.owner_id} {self.name!r}>"
        )
