"""`cloudsim provider`: configure cloud providers (settings stored encrypted)."""

from __future__ import annotations

import sys

import click

from cloudsim.audit.service import record
from cloudsim.auth.policy import SYSTEM
from cloudsim.cli import app_context, emit, reports_errors
from cloudsim.cli.files import LoadedText, TextFile
from cloudsim.errors import CloudSimError, InvalidInput
from cloudsim.providers.service import (
    PROVIDERS,
    configure_provider,
    ec2_settings,
    provider_settings,
    servers_settings,
)


@click.group()
def provider() -> None:
    """Configure and list the providers constellations can be launched on."""


@provider.group("configure")
def configure() -> None:
    """Store a provider's settings, encrypted; launches use them from then on."""


@configure.command("ec2")
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
def configure_ec2(
    region: str,
    access_key: str,
    secret_key_stdin: bool,
    image: str,
    sizes: tuple[str, ...],
    endpoint: str | None,
) -> None:
    """Amazon EC2 (or an EC2-compatible API): credentials, region, image, instance types."""
    secret = sys.stdin.readline().strip()
    try:
        settings = ec2_settings(
            access_key=access_key,
            secret_key=secret,
            region=region,
            image=image,
            sizes=sizes,
            endpoint=endpoint,
        )
    except InvalidInput as exc:
        raise click.BadParameter(str(exc), param_hint="--size") from None
    with app_context():
        configure_provider("ec2", settings)
        record(
            "provider.configure",
            SYSTEM,
            target_type="provider",
            target_id="ec2",
            region=region,
            image=image,
        )
        click.echo(f"ec2 configured (region {region}, image {image})")


@configure.command("servers")
@click.option(
    "--inventory",
    "inventory_file",
    required=True,
    type=TextFile(),
    help="YAML list of servers (name, address, private_ip, network, cidr, "
    "private_key, ...); see provisioners/providers/servers/README.md.",
)
@reports_errors
def configure_servers(inventory_file: LoadedText) -> None:
    """Existing machines reachable by SSH (e.g. bare-metal servers), from an inventory file."""
    inventory = servers_settings(inventory_file.text, inventory_file.name)["inventory"]
    if not isinstance(inventory, list):
        raise click.ClickException(f"{inventory_file.name}: expected a list of servers")
    with app_context():
        configure_provider("servers", {"inventory": inventory})
        record(
            "provider.configure",
            SYSTEM,
            target_type="provider",
            target_id="servers",
            servers=len(inventory),
        )
        click.echo(
            f"servers configured ({len(inventory)} servers); keep the file safe or "
            "delete it: the keys are now stored encrypted"
        )


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
                rows.append({"name": name, "configured": True, "region": settings.get("region")})
        lines = "\n".join(
            f"{r['name']}\t{'configured' if r['configured'] else 'not configured'}"
            f"\t{r['region'] or ''}".rstrip()
            for r in rows
        )
        emit(rows, as_json, lines)
