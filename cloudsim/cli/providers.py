"""`cloudsim provider`: configure cloud providers (settings stored encrypted)."""

from __future__ import annotations

import sys

import click

from cloudsim.audit.service import record
from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.fleet.providers import PROVIDERS, configure_provider, provider_settings


@click.group()
def provider() -> None:
    """Configure and list the providers constellations can be launched on."""


@provider.command("configure")
@click.argument("name", type=click.Choice(["ec2"]))
@click.option("--region", required=True, help="e.g. us-east-1")
@click.option("--access-key", required=True, help="Access key id.")
@click.option(
    "--secret-key-stdin",
    is_flag=True,
    required=True,
    help="Read the secret access key from standard input (never the command line).",
)
@click.option("--image", required=True, help="Machine image (AMI) every machine starts from.")
@click.option(
    "--size",
    "sizes",
    multiple=True,
    metavar="LOGICAL=TYPE",
    help="Instance type per logical size, e.g. gpu=g4dn.xlarge (repeatable).",
)
@click.option("--endpoint", help="An EC2-compatible API URL instead of AWS's.")
@reports_errors
def configure(
    name: str,
    region: str,
    access_key: str,
    secret_key_stdin: bool,
    image: str,
    sizes: tuple[str, ...],
    endpoint: str | None,
) -> None:
    """Store a provider's settings, encrypted; launches use them from then on."""
    secret = sys.stdin.readline().strip()
    size_map = {}
    for item in sizes:
        logical, _, instance_type = item.partition("=")
        if not logical or not instance_type:
            raise click.BadParameter(f"{item!r} is not LOGICAL=TYPE", param_hint="--size")
        size_map[logical] = instance_type
    with app_context():
        settings = {
            "access_key": access_key,
            "secret_key": secret,
            "region": region,
            "image": image,
            "sizes": size_map,
        }
        if endpoint:
            settings["endpoint"] = endpoint
        configure_provider(name, settings)
        record(
            "provider.configure",
            None,
            target_type="provider",
            target_id=name,
            region=region,
            image=image,
        )
        db.session.commit()
        click.echo(f"{name} configured (region {region}, image {image})")


@provider.command("list")
@click.option("--json", "as_json", is_flag=True, help="Print JSON.")
@reports_errors
def list_providers(as_json: bool) -> None:
    """List providers and whether each is ready to use (secrets are never shown)."""
    with app_context():
        rows: list[dict[str, str | bool | None]] = []
        for name in PROVIDERS:
            if name == "local":
                rows.append({"name": name, "configured": True, "region": None})
                continue
            try:
                settings = provider_settings(name)
            except CloudSimError:
                rows.append({"name": name, "configured": False, "region": None})
            else:
                rows.append({"name": name, "configured": True, "region": settings["region"]})
        lines = "\n".join(
            f"{r['name']}\t{'configured' if r['configured'] else 'not configured'}"
            f"\t{r['region'] or ''}".rstrip()
            for r in rows
        )
        emit(rows, as_json, lines)
