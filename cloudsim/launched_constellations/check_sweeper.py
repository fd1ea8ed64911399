"""The sweeper of verification's VPN check clients: revoke what a dead check left valid.

A check records its certificate's serial before the key exists anywhere (vpn_check.py). If
its job died and nothing resumes it, the serial stays pending; this beat task revokes it on
the router and removes the check's folder, once no job of the constellation is alive.
"""

from __future__ import annotations

import logging
from datetime import timedelta

from celery import shared_task
from flask import current_app
from sqlalchemy import select

from cloudsim.config import Config
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.launched_constellations import vpn
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair
from cloudsim.launched_constellations.vpn_check import clean_up_checks
from cloudsim.models import Constellation, ConstellationState, Job, JobState, utcnow
from provisioners.remote.ssh import ConnectPolicy, SSHError, SSHExecutor

log = logging.getLogger(__name__)


def _job_alive(constellation: Constellation, config: Config) -> bool:
    """Say whether a job of the constellation is queued or running with a live lease."""
    fresh = utcnow() - timedelta(seconds=config.job_lease_seconds)
    alive = db.session.scalar(
        select(Job.id)
        .where(
            Job.target_type == "constellation",
            Job.target_id == constellation.id,
            (Job.state == JobState.QUEUED)
            | ((Job.state == JobState.RUNNING) & (Job.heartbeat_at >= fresh)),
        )
        .limit(1)
    )
    return alive is not None


def sweep_checks(config: Config) -> list[int]:
    """Revoke the pending check certificates of constellations no live job works on; return
    the serials revoked (a router out of reach is tried again at the next sweep)."""
    revoked: list[int] = []
    live = db.session.scalars(
        select(Constellation).where(Constellation.state != ConstellationState.TERMINATED)
    ).all()
    for constellation in live:
        if not vpn.pending_check_certificates(constellation) or _job_alive(constellation, config):
            continue
        router = next((m for m in constellation.machines if m.role == "router"), None)
        if router is None:
            continue
        keys = constellation_keypair(constellation)
        reach = targets(constellation, keys, config)
        executor = SSHExecutor(
            machine_host_keys(constellation),
            secrets=[keys.private],
            connect_policy=ConnectPolicy(deadline=30),
        )
        try:
            with executor:
                revoked += clean_up_checks(
                    executor, constellation, reach[router.name], db.session.commit, log.info
                )
        except (CloudSimError, SSHError) as exc:
            db.session.rollback()
            log.warning(
                "%s: cannot revoke its VPN check certificates yet: %s", constellation.name, exc
            )
    db.session.commit()
    return revoked


@shared_task(name="cloudsim.launched_constellations.sweep_vpn_checks")
def sweep_vpn_checks() -> int:
    """Revoke what dead VPN checks left valid (the beat runs it every minute)."""
    return len(sweep_checks(current_app.config["CLOUDSIM"]))
