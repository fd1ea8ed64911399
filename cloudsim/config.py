"""Configuration: one Config object fed by CLOUDSIM_* environment variables."""

from __future__ import annotations

import ipaddress
import json
import os
import secrets
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from urllib.parse import urlsplit

from cryptography.fernet import Fernet


class ConfigError(Exception):
    """A configuration value is missing or malformed."""


def _bool(value: str) -> bool:
    lowered = value.strip().lower()
    if lowered in {"1", "true", "yes", "on"}:
        return True
    if lowered in {"0", "false", "no", "off", ""}:
        return False
    raise ValueError(f"expected true/false, got {value!r}")


@dataclass(frozen=True)
class Setting:
    """One CLOUDSIM_* variable: its default and what it means (the configuration page's row)."""

    default: str
    help: str


# Every variable CloudSim reads. An empty default means "derived at start-up" (see help).
SETTINGS: dict[str, Setting] = {
    "CLOUDSIM_INSTANCE_DIR": Setting(
        "./instance", "Folder for the database, keys, Redis data, logs"
    ),
    "CLOUDSIM_DATABASE_URL": Setting(
        "", "SQLAlchemy URL; default SQLite at INSTANCE_DIR/cloudsim.db (production: PostgreSQL)"
    ),
    "CLOUDSIM_REDIS_URL": Setting(
        "", "Redis for the job queue and login limits; unset = CloudSim starts its own"
    ),
    "CLOUDSIM_REDIS_PORT": Setting(
        "6390", "Port of the private Redis started when no URL is given"
    ),
    "CLOUDSIM_SECRET_KEY": Setting(
        "", "Signs sessions and CSRF tokens; default generated once into INSTANCE_DIR/secret.key"
    ),
    "CLOUDSIM_ENCRYPTION_KEYS": Setting(
        "",
        "Comma-separated Fernet keys for secrets at rest, newest first (rotation); default "
        "generated once into INSTANCE_DIR/encryption.key",
    ),
    "CLOUDSIM_ADMIN_EMAIL": Setting("admin@example.org", "E-mail of the first admin"),
    "CLOUDSIM_ADMIN_PASSWORD": Setting(
        "", "Password of the first admin; unset = generated and printed once"
    ),
    "CLOUDSIM_ADMIN_TOKEN": Setting(
        "",
        "An API token (cst_...) the first admin gets at start-up (how a master calls its instance)",
    ),
    "CLOUDSIM_BIND": Setting("127.0.0.1:5000", "Address the web server listens on"),
    "CLOUDSIM_TLS_CERT": Setting(
        "",
        "PEM certificate file: when set (with CLOUDSIM_TLS_KEY) the web server speaks HTTPS only",
    ),
    "CLOUDSIM_TLS_KEY": Setting("", "PEM private key file of CLOUDSIM_TLS_CERT"),
    "CLOUDSIM_INSTANCE_POLL_SECONDS": Setting(
        "30", "How often a master checks its team instances' health (and reconciles them)"
    ),
    "CLOUDSIM_WEB_WORKERS": Setting(
        "", "gunicorn worker processes; default one per CPU core, at least 2"
    ),
    "CLOUDSIM_WEB_THREADS": Setting(
        "4", "Threads per gunicorn worker; clients' idle keep-alive connections hold none"
    ),
    "CLOUDSIM_WORKER_CONCURRENCY": Setting("2", "Celery worker processes"),
    "CLOUDSIM_SECURE_COOKIES": Setting("false", "Mark cookies Secure (set true behind HTTPS)"),
    "CLOUDSIM_SESSION_HOURS": Setting("12", "Lifetime of a login session"),
    "CLOUDSIM_LOGIN_LIMIT": Setting(
        "5 per minute;30 per hour", "Failed logins allowed per address and account"
    ),
    "CLOUDSIM_JOB_VISIBILITY_TIMEOUT": Setting(
        "3600", "Seconds before Redis re-delivers an unacknowledged job message"
    ),
    "CLOUDSIM_JOB_LEASE_SECONDS": Setting(
        "30", "A running job whose worker has not renewed its lease this long is resumed elsewhere"
    ),
    "CLOUDSIM_JOB_STALL_SECONDS": Setting(
        "300",
        "A running job that reports nothing (no stage, progress or log line) this long is stopped"
        " at its next remote step and fails with the reason, freeing its worker slot",
    ),
    "CLOUDSIM_STALE_JOB_SECONDS": Setting(
        "300", "A job queued this long without starting is sent to the queue again"
    ),
    "CLOUDSIM_LOCAL_PREFIX": Setting(
        "cs", "Prefix of everything the local provider creates (namespaces, mounts, state)"
    ),
    "CLOUDSIM_LOCAL_SUBNET_POOL": Setting(
        "10.211.0.0/16", "Private subnets of local constellations are carved from this pool"
    ),
    "CLOUDSIM_LOCAL_PUBLIC_CIDR": Setting(
        "198.18.0.0/24", "The local provider's shared 'public' network"
    ),
    "CLOUDSIM_LOCAL_MAX_HOSTS": Setting(
        "0", "Most hosts the local provider runs at once; 0 = as many as the machine allows"
    ),
    "CLOUDSIM_LOCAL_HOST_MEMORY_MB": Setting(
        "0",
        "Memory the local provider counts per host in its capacity; 0 = each role's figure "
        "measured by bench/host_memory.py",
    ),
    "CLOUDSIM_LOCAL_MEMORY_RESERVE_MB": Setting(
        "2048", "Memory the local provider leaves to the controller when counting its capacity"
    ),
    "CLOUDSIM_VERIFY_RETRY_SECONDS": Setting(
        "120", "How long verification retries failed checks (with backoff) before it gives up"
    ),
    "CLOUDSIM_MACHINE_PYTHON": Setting(
        "/usr/bin/python3",
        "A Python like the machines' (Debian 12's), used to build the wheels they install",
    ),
    "CLOUDSIM_ARGON2_TIME_COST": Setting("3", "Argon2id passes when hashing a password"),
    "CLOUDSIM_ARGON2_MEMORY_KIB": Setting("65536", "Argon2id memory per password hash, KiB"),
    "CLOUDSIM_LOG_LEVEL": Setting("INFO", "Log level of the web server and workers"),
    "CLOUDSIM_LOG_FORMAT": Setting(
        "text",
        "text, or json: one JSON object a line (request, user, job, run, constellation ids) from"
        " the web server, the workers and the beat",
    ),
    "CLOUDSIM_METRICS_NETWORKS": Setting(
        "127.0.0.0/8,::1/128",
        "Comma-separated networks whose addresses may read GET /metrics without a token",
    ),
    "CLOUDSIM_METRICS_TOKEN": Setting(
        "", "A bearer token that also opens GET /metrics (from anywhere); empty: none"
    ),
    "CLOUDSIM_READY_MIN_FREE_MB": Setting(
        "1024", "GET /readyz fails when the instance folder's disk has less free than this"
    ),
    "CLOUDSIM_READY_OUTBOX_SECONDS": Setting(
        "3600",
        "GET /readyz fails when a finished run has waited this long in the portal outbox",
    ),
    "CLOUDSIM_ARTIFACT_STORE": Setting(
        "local",
        "Where run logs are kept: local (a folder) or a libcloud storage provider "
        "(s3, google_storage, azure_blobs, ...)",
    ),
    "CLOUDSIM_ARTIFACT_DIR": Setting(
        "", "Folder of the local log store; default INSTANCE_DIR/artifacts"
    ),
    "CLOUDSIM_ARTIFACT_CONTAINER": Setting("cloudsim-logs", "Container (bucket) of the run logs"),
    "CLOUDSIM_ARTIFACT_KEY": Setting("", "Access key of the object store (libcloud providers)"),
    "CLOUDSIM_ARTIFACT_SECRET": Setting("", "Secret key of the object store (libcloud providers)"),
    "CLOUDSIM_ARTIFACT_OPTIONS": Setting(
        "{}", "JSON object of extra libcloud storage driver arguments (region, host, ...)"
    ),
    "CLOUDSIM_LEADERBOARD_FOR_USERS": Setting(
        "all", "What team users see of the leaderboard: all (every team), own (their row), none"
    ),
    "CLOUDSIM_RUN_SUPERVISE_SECONDS": Setting(
        "5", "How often live runs are checked for their end (time limit, falls, window, stop)"
    ),
    "CLOUDSIM_RUN_LIVE_SECONDS": Setting(
        "1",
        "How often a running run's live figures (simulated time, RTF, score, bits) are read from"
        " its machines into Redis, where its page, the API and `cloudsim run watch` read them",
    ),
    "CLOUDSIM_RUN_SILENT_SECONDS": Setting(
        "5",
        "A running run whose simulator has not answered, or whose simulated time has not moved,"
        " for this long is flagged on its page (RUN-SIM-SILENT)",
    ),
    "CLOUDSIM_RUN_RTF_ALERT": Setting(
        "0.9", "A running run whose real-time factor stays under this is flagged (RUN-SIM-SLOW)"
    ),
    "CLOUDSIM_RUN_RTF_ALERT_SECONDS": Setting(
        "10", "How long the real-time factor must stay under CLOUDSIM_RUN_RTF_ALERT to be flagged"
    ),
    "CLOUDSIM_SIM_MIN_RTF": Setting(
        "1.0",
        "The real-time factor a simulator machine must hold in launch verification's self-test"
        " (with every sensor on); a slower machine fails verification (LAUNCH-SIM-SLOW)",
    ),
    "CLOUDSIM_RUN_GRACE_SECONDS": Setting(
        "120", "Wall seconds past a run's timeout after which CloudSim stops it regardless"
    ),
    "CLOUDSIM_RUN_PROBE_SECONDS": Setting(
        "4",
        "How long a supervision beat waits for the machines' answers; a slower machine is reported"
        " late and its answer applied by a later beat",
    ),
    "CLOUDSIM_SSH_CONNECTIONS": Setting(
        "256", "SSH connections a worker process keeps open between beats (oldest closed first)"
    ),
    "CLOUDSIM_PORTAL_URL": Setting(
        "",
        "On a master: the https://HOST:PORT/ its team instances upload runs to (its web server,"
        " serving `cloudsim portal certificate`'s files); empty: instances upload nothing",
    ),
    "CLOUDSIM_PORTAL_UPLOAD_SECONDS": Setting(
        "10", "On a team instance: how often the outbox of finished runs is sent to the master"
    ),
    "CLOUDSIM_PORTAL_RETRY_SECONDS": Setting(
        "5", "On a team instance: the first wait after a failed upload; doubles up to 600 s"
    ),
    "CLOUDSIM_PORTAL_STAGING_HOURS": Setting(
        "48",
        "On a master: how long the part of a log whose upload stopped arriving is kept (a piece"
        " arriving later starts that log again from 0)",
    ),
    "CLOUDSIM_PORTAL_WINDOW_GRACE_SECONDS": Setting(
        "900",
        "On a master: how long after its task's window an uploaded run may have ended (its stop"
        " job collecting logs) before it is refused",
    ),
    "CLOUDSIM_RANK_UNVERIFIED": Setting(
        "true",
        "Whether a finished run ranks before its replay verified it (marked unverified on the"
        " leaderboard); false: only verified or officer-accepted runs rank",
    ),
    "CLOUDSIM_VIEWER_LIVE_HZ": Setting(
        "10", "Frames per simulated second a live 3D viewer receives (the relay's rate)"
    ),
    "CLOUDSIM_VIEWER_LIVE_DELAY_MS": Setting(
        "1500", "How far behind the newest relayed frame a live 3D view plays (smooths polling)"
    ),
    "CLOUDSIM_VIEWER_POLL_MS": Setting(
        "250", "Shortest interval between two live-frame requests of one viewer (else 429)"
    ),
    "CLOUDSIM_VIEWER_MAX_LIVE": Setting(
        "8", "Live 3D viewers allowed per run at once (one more gets 503)"
    ),
    "CLOUDSIM_SMTP_HOST": Setting("", "SMTP server for run e-mails; empty: no e-mails are sent"),
    "CLOUDSIM_SMTP_PORT": Setting("25", "Port of the SMTP server"),
    "CLOUDSIM_SMTP_SENDER": Setting("cloudsim@localhost", "From: address of run e-mails"),
    "CLOUDSIM_SMTP_STARTTLS": Setting("false", "Upgrade the SMTP connection with STARTTLS"),
    "CLOUDSIM_SMTP_USERNAME": Setting("", "SMTP login; empty: no login"),
    "CLOUDSIM_SMTP_PASSWORD": Setting("", "SMTP password (never logged)"),
    "CLOUDSIM_PUBLIC_URL": Setting(
        "", "This CloudSim's address (https://HOST/) for links in e-mails and webhook events"
    ),
    "CLOUDSIM_NOTIFY_ATTEMPTS": Setting(
        "6", "Tries of one e-mail batch or webhook delivery before it is given up"
    ),
    "CLOUDSIM_NOTIFY_RETRY_SECONDS": Setting(
        "30", "First wait before a failed e-mail or webhook delivery is retried; doubles each time"
    ),
}


@dataclass(frozen=True)
class Config:
    """Everything the app needs to start, resolved from the environment once."""

    instance_dir: Path
    database_url: str
    redis_url: str | None
    redis_port: int
    secret_key: str
    encryption_keys: tuple[str, ...] = field(repr=False)
    admin_email: str
    admin_password: str | None = field(repr=False)
    admin_token: str | None = field(repr=False)
    bind: str
    tls_cert: str
    tls_key: str
    instance_poll_seconds: int
    web_workers: int
    web_threads: int
    worker_concurrency: int
    secure_cookies: bool
    session_hours: int
    login_limit: str
    job_visibility_timeout: int
    job_lease_seconds: int
    job_stall_seconds: int
    stale_job_seconds: int
    local_prefix: str
    local_subnet_pool: str
    local_public_cidr: str
    local_max_hosts: int
    local_host_memory_mb: int
    local_memory_reserve_mb: int
    verify_retry_seconds: int
    machine_python: str
    argon2_time_cost: int
    argon2_memory_kib: int
    log_level: str
    log_format: str
    metrics_networks: tuple[str, ...]
    metrics_token: str = field(repr=False)
    ready_min_free_mb: int
    ready_outbox_seconds: int
    artifact_store: str
    artifact_dir: Path
    artifact_container: str
    artifact_key: str
    artifact_secret: str = field(repr=False)
    artifact_options: dict[str, object]
    leaderboard_for_users: str
    run_supervise_seconds: int
    run_grace_seconds: int
    run_live_seconds: int
    run_silent_seconds: int
    run_rtf_alert: float
    run_rtf_alert_seconds: int
    sim_min_rtf: float
    run_probe_seconds: int
    ssh_connections: int
    portal_url: str
    portal_upload_seconds: int
    portal_retry_seconds: int
    portal_window_grace_seconds: int
    portal_staging_hours: int
    rank_unverified: bool
    viewer_live_hz: int
    viewer_live_delay_ms: int
    viewer_poll_ms: int
    viewer_max_live: int
    smtp_host: str
    smtp_port: int
    smtp_sender: str
    smtp_starttls: bool
    smtp_username: str
    smtp_password: str = field(repr=False)
    public_url: str
    notify_attempts: int
    notify_retry_seconds: float
    testing: bool = False

    def __repr__(self) -> str:
        shown = ", ".join(
            f"{f.name}={getattr(self, f.name)!r}"
            for f in fields(self)
            if f.name
            not in {
                "secret_key",
                "encryption_keys",
                "admin_password",
                "admin_token",
                "artifact_secret",
                "metrics_token",
                "smtp_password",
            }
        )
        return f"Config({shown})"

    @property
    def effective_redis_url(self) -> str:
        """Return the configured Redis URL or the private instance's."""
        return self.redis_url or f"redis://127.0.0.1:{self.redis_port}/0"

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None, **overrides: object) -> Config:
        """Build a Config from CLOUDSIM_* variables, generating instance keys on first use."""
        env = os.environ if environ is None else environ

        def get(name: str) -> str:
            return env.get(name, SETTINGS[name].default)

        def number(name: str) -> int:
            try:
                return int(get(name))
            except ValueError:
                raise ConfigError(f"{name} must be a whole number, got {get(name)!r}") from None

        def positive(name: str) -> int:
            value = number(name)
            if value < 1:
                raise ConfigError(f"{name} must be at least 1, got {value}")
            return value

        def real(name: str) -> float:
            try:
                value = float(get(name))
            except ValueError:
                raise ConfigError(f"{name} must be a number, got {get(name)!r}") from None
            if not 0 <= value < 100:
                raise ConfigError(f"{name} must be between 0 and 100, got {value}")
            return value

        instance_dir = Path(str(overrides.pop("instance_dir", get("CLOUDSIM_INSTANCE_DIR"))))
        instance_dir = instance_dir.expanduser().resolve()
        # Keys, the database and logs live here: no other local user may read them.
        instance_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
        instance_dir.chmod(0o700)
        try:
            secure = _bool(get("CLOUDSIM_SECURE_COOKIES"))
        except ValueError as exc:
            raise ConfigError(f"CLOUDSIM_SECURE_COOKIES: {exc}") from None
        keys = get("CLOUDSIM_ENCRYPTION_KEYS") or _instance_secret(
            instance_dir / "encryption.key", lambda: Fernet.generate_key().decode()
        )
        encryption_keys = tuple(k.strip() for k in keys.split(",") if k.strip())
        for key in encryption_keys:
            try:
                Fernet(key)
            except ValueError:
                raise ConfigError("CLOUDSIM_ENCRYPTION_KEYS holds a malformed Fernet key") from None
        if bool(get("CLOUDSIM_TLS_CERT")) != bool(get("CLOUDSIM_TLS_KEY")):
            raise ConfigError(
                "CLOUDSIM_TLS_CERT and CLOUDSIM_TLS_KEY go together: set both or none"
            )
        if get("CLOUDSIM_ADMIN_TOKEN") and not get("CLOUDSIM_ADMIN_TOKEN").startswith("cst_"):
            raise ConfigError("CLOUDSIM_ADMIN_TOKEN must be an API token (cst_...)")
        values: dict[str, object] = dict(
            instance_dir=instance_dir,
            database_url=get("CLOUDSIM_DATABASE_URL")
            or f"sqlite:///{instance_dir / 'cloudsim.db'}",
            redis_url=get("CLOUDSIM_REDIS_URL") or None,
            redis_port=number("CLOUDSIM_REDIS_PORT"),
            secret_key=get("CLOUDSIM_SECRET_KEY")
            or _instance_secret(instance_dir / "secret.key", lambda: secrets.token_urlsafe(48)),
            encryption_keys=encryption_keys,
            admin_email=get("CLOUDSIM_ADMIN_EMAIL"),
            admin_password=get("CLOUDSIM_ADMIN_PASSWORD") or None,
            admin_token=get("CLOUDSIM_ADMIN_TOKEN") or None,
            bind=get("CLOUDSIM_BIND"),
            tls_cert=get("CLOUDSIM_TLS_CERT"),
            tls_key=get("CLOUDSIM_TLS_KEY"),
            instance_poll_seconds=number("CLOUDSIM_INSTANCE_POLL_SECONDS"),
            web_workers=positive("CLOUDSIM_WEB_WORKERS")
            if get("CLOUDSIM_WEB_WORKERS")
            else max(2, os.cpu_count() or 1),
            web_threads=positive("CLOUDSIM_WEB_THREADS"),
            worker_concurrency=number("CLOUDSIM_WORKER_CONCURRENCY"),
            secure_cookies=secure,
            session_hours=number("CLOUDSIM_SESSION_HOURS"),
            login_limit=get("CLOUDSIM_LOGIN_LIMIT"),
            job_visibility_timeout=number("CLOUDSIM_JOB_VISIBILITY_TIMEOUT"),
            job_lease_seconds=number("CLOUDSIM_JOB_LEASE_SECONDS"),
            job_stall_seconds=positive("CLOUDSIM_JOB_STALL_SECONDS"),
            stale_job_seconds=number("CLOUDSIM_STALE_JOB_SECONDS"),
            local_prefix=get("CLOUDSIM_LOCAL_PREFIX"),
            local_subnet_pool=get("CLOUDSIM_LOCAL_SUBNET_POOL"),
            local_public_cidr=get("CLOUDSIM_LOCAL_PUBLIC_CIDR"),
            local_max_hosts=number("CLOUDSIM_LOCAL_MAX_HOSTS"),
            local_host_memory_mb=number("CLOUDSIM_LOCAL_HOST_MEMORY_MB"),
            local_memory_reserve_mb=number("CLOUDSIM_LOCAL_MEMORY_RESERVE_MB"),
            verify_retry_seconds=number("CLOUDSIM_VERIFY_RETRY_SECONDS"),
            machine_python=get("CLOUDSIM_MACHINE_PYTHON"),
            argon2_time_cost=number("CLOUDSIM_ARGON2_TIME_COST"),
            argon2_memory_kib=number("CLOUDSIM_ARGON2_MEMORY_KIB"),
            log_level=get("CLOUDSIM_LOG_LEVEL").upper(),
            log_format=_choice("CLOUDSIM_LOG_FORMAT", get, ("text", "json")),
            metrics_networks=_networks("CLOUDSIM_METRICS_NETWORKS", get),
            metrics_token=get("CLOUDSIM_METRICS_TOKEN"),
            ready_min_free_mb=number("CLOUDSIM_READY_MIN_FREE_MB"),
            ready_outbox_seconds=positive("CLOUDSIM_READY_OUTBOX_SECONDS"),
            artifact_store=get("CLOUDSIM_ARTIFACT_STORE").strip().lower(),
            artifact_dir=Path(get("CLOUDSIM_ARTIFACT_DIR") or instance_dir / "artifacts"),
            artifact_container=get("CLOUDSIM_ARTIFACT_CONTAINER"),
            artifact_key=get("CLOUDSIM_ARTIFACT_KEY"),
            artifact_secret=get("CLOUDSIM_ARTIFACT_SECRET"),
            artifact_options=_json_object("CLOUDSIM_ARTIFACT_OPTIONS", get),
            leaderboard_for_users=_choice(
                "CLOUDSIM_LEADERBOARD_FOR_USERS", get, ("all", "own", "none")
            ),
            run_supervise_seconds=number("CLOUDSIM_RUN_SUPERVISE_SECONDS"),
            run_grace_seconds=number("CLOUDSIM_RUN_GRACE_SECONDS"),
            run_live_seconds=positive("CLOUDSIM_RUN_LIVE_SECONDS"),
            run_silent_seconds=positive("CLOUDSIM_RUN_SILENT_SECONDS"),
            run_rtf_alert=real("CLOUDSIM_RUN_RTF_ALERT"),
            run_rtf_alert_seconds=number("CLOUDSIM_RUN_RTF_ALERT_SECONDS"),
            sim_min_rtf=real("CLOUDSIM_SIM_MIN_RTF"),
            run_probe_seconds=positive("CLOUDSIM_RUN_PROBE_SECONDS"),
            ssh_connections=positive("CLOUDSIM_SSH_CONNECTIONS"),
            portal_url=_portal_url(get("CLOUDSIM_PORTAL_URL")),
            portal_upload_seconds=positive("CLOUDSIM_PORTAL_UPLOAD_SECONDS"),
            portal_retry_seconds=positive("CLOUDSIM_PORTAL_RETRY_SECONDS"),
            portal_window_grace_seconds=number("CLOUDSIM_PORTAL_WINDOW_GRACE_SECONDS"),
            portal_staging_hours=positive("CLOUDSIM_PORTAL_STAGING_HOURS"),
            rank_unverified=_flag("CLOUDSIM_RANK_UNVERIFIED", get),
            viewer_live_hz=number("CLOUDSIM_VIEWER_LIVE_HZ"),
            viewer_live_delay_ms=number("CLOUDSIM_VIEWER_LIVE_DELAY_MS"),
            viewer_poll_ms=number("CLOUDSIM_VIEWER_POLL_MS"),
            viewer_max_live=number("CLOUDSIM_VIEWER_MAX_LIVE"),
            smtp_host=get("CLOUDSIM_SMTP_HOST"),
            smtp_port=positive("CLOUDSIM_SMTP_PORT"),
            smtp_sender=get("CLOUDSIM_SMTP_SENDER"),
            smtp_starttls=_flag("CLOUDSIM_SMTP_STARTTLS", get),
            smtp_username=get("CLOUDSIM_SMTP_USERNAME"),
            smtp_password=get("CLOUDSIM_SMTP_PASSWORD"),
            public_url=get("CLOUDSIM_PUBLIC_URL").rstrip("/"),
            notify_attempts=positive("CLOUDSIM_NOTIFY_ATTEMPTS"),
            notify_retry_seconds=positive("CLOUDSIM_NOTIFY_RETRY_SECONDS"),
        )
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]


def _flag(name: str, get: Callable[[str], str]) -> bool:
    """Return a yes/no setting, or a clear error naming it."""
    try:
        return _bool(get(name))
    except ValueError as exc:
        raise ConfigError(f"{name}: {exc}") from None


def _portal_url(value: str) -> str:
    """Return the portal's base URL (https, a host, a port), normalised; empty when unset."""
    value = value.strip()
    if not value:
        return ""
    parsed = urlsplit(value)
    try:
        port = parsed.port
    except ValueError:
        port = None
    if parsed.scheme != "https" or not parsed.hostname or port is None:
        raise ConfigError(f"CLOUDSIM_PORTAL_URL must be https://HOST:PORT/, got {value!r}")
    return f"https://{parsed.hostname}:{port}/"


def _json_object(name: str, get: Callable[[str], str]) -> dict[str, object]:
    try:
        value = json.loads(get(name) or "{}")
    except ValueError as exc:
        raise ConfigError(f"{name} must be a JSON object: {exc}") from None
    if not isinstance(value, dict):
        raise ConfigError(f"{name} must be a JSON object, got {get(name)!r}")
    return value


def _networks(name: str, get: Callable[[str], str]) -> tuple[str, ...]:
    """Return the comma-separated networks of a setting, each checked and normalised."""
    found = []
    for part in get(name).split(","):
        if part.strip():
            try:
                found.append(str(ipaddress.ip_network(part.strip(), strict=False)))
            except ValueError:
                raise ConfigError(f"{name}: {part.strip()!r} is not a network") from None
    return tuple(found)


def _choice(name: str, get: Callable[[str], str], choices: tuple[str, ...]) -> str:
    value = get(name).strip().lower()
    if value not in choices:
        raise ConfigError(f"{name} must be one of {', '.join(choices)}, got {value!r}")
    return value


def _instance_secret(path: Path, generate: object) -> str:
    """Read a generated secret from the instance folder, creating it (mode 0600) the first time."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return path.read_text().strip()
    value = generate()  # type: ignore[operator]
    with os.fdopen(fd, "w") as handle:
        handle.write(value + "\n")
    return str(value)
