"""What the fuzzers share: a populated app, the personas, the seed, and the log watch."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from flask import Flask
from hypothesis import HealthCheck, Phase, seed, settings

from cloudsim.extensions import db
from cloudsim.models import Constellation, ConstellationState, User
from tests.competition.support import finished_run, open_task, ready_constellation

PERSONAS = ("anon", "user_a", "user_b", "officer", "admin")
# One seed for every run, so that a failure reproduces; CLOUDSIM_FUZZ_SEED explores others.
SEED = int(os.environ.get("CLOUDSIM_FUZZ_SEED", "20261122"))


def seeded(examples: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Decorate a Hypothesis test: `examples` at most, the fixed seed, no example database."""

    def decorate(test: Callable[..., None]) -> Callable[..., None]:
        return seed(SEED)(  # type: ignore[no-any-return]
            settings(
                max_examples=examples,
                deadline=None,
                database=None,
                phases=[Phase.explicit, Phase.generate],
                suppress_health_check=list(HealthCheck),
            )(test)
        )

    return decorate


def populate(app: Flask, people: dict[str, User | None], tmp: Path) -> None:
    """Give team A a ready constellation, an open task and a finished run with a log."""
    team_a = people["user_a"].team  # type: ignore[union-attr]
    constellation = Constellation(name="fuzz-vrc", kind="vrc", provider="local", team_id=team_a.id)
    constellation.state = ConstellationState.READY
    db.session.add(constellation)
    db.session.commit()
    ready_constellation(constellation.id)
    finished_run(open_task(team_a.id), constellation.id, tmp)
    open_task(team_a.id)


class Tracebacks(logging.Handler):
    """Collect every log record that carries an exception: the app hit something unplanned."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info or record.levelno >= logging.ERROR:
            self.records.append(record)

    def report(self) -> str:
        return "\n".join(self.format(r) for r in self.records[:5])


@contextmanager
def watched_log() -> Iterator[Tracebacks]:
    """Attach a Tracebacks handler to CloudSim's logger for the duration."""
    handler = Tracebacks()
    handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
    logger = logging.getLogger("cloudsim")
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
