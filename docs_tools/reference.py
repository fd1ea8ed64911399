"""MkDocs hook: write the reference pages from the code, so they can never drift from it.

The CLI comes from click, the configuration from `cloudsim.config.SETTINGS`, the API from
the OpenAPI document the app serves, the error codes from `cloudsim.error_codes`.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click
from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

# A page that holds this line gets the error codes' table in its place.
ERROR_CODES_TABLE = "<!-- error codes table: generated from cloudsim/error_codes.py -->"


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add the generated reference pages (and the OpenAPI document) to the site's files."""
    spec = openapi_document()
    pages = {
        "reference/cli.md": cli_page(),
        "reference/configuration.md": configuration_page(),
        "reference/api.md": api_page(spec),
    }
    # The machines' packages keep their READMEs beside their code; the site shows them as is.
    root = Path(config.config_file_path).parent
    pages["reference/drcsim.md"] = (root / "simulator" / "README.md").read_text()
    pages["reference/csrouter.md"] = (root / "router" / "README.md").read_text()
    for path, text in pages.items():
        files.append(File.generated(config, path, content=text))
    files.append(File.generated(config, "reference/openapi.json", content=json.dumps(spec)))
    return files


def cli_page() -> str:
    """Return every `cloudsim` command's --help, from click itself."""
    from cloudsim.cli import main

    lines = [
        "# Command line",
        "",
        "Every `cloudsim` command and its options, as `cloudsim COMMAND --help` prints them",
        "(this page is generated from the commands themselves).",
        "",
    ]
    for path, ctx in _commands(main, "cloudsim"):
        lines += [f"## `{path}`", "", "```text", ctx.get_help().rstrip(), "```", ""]
    return "\n".join(lines)


def _commands(
    command: click.Command, path: str, parent: click.Context | None = None
) -> Iterator[tuple[str, click.Context]]:
    # the command's own context settings (-h as well as --help), at a fixed width
    settings = {**command.context_settings, "terminal_width": 88, "max_content_width": 88}
    ctx = command.context_class(
        command, info_name=path.rsplit(" ", 1)[-1], parent=parent, **settings
    )
    yield path, ctx
    if isinstance(command, click.Group):
        for name in command.list_commands(ctx):
            sub = command.get_command(ctx, name)
            if sub is not None and not sub.hidden:
                yield from _commands(sub, f"{path} {name}", ctx)


def configuration_page() -> str:
    """Return the table of every CLOUDSIM_* setting, from `SETTINGS`."""
    from cloudsim.config import SETTINGS

    lines = [
        "# Configuration",
        "",
        "One source: `CLOUDSIM_*` environment variables, read once into",
        "`cloudsim.config.Config` when a command starts. An empty default means the value is",
        "derived at start-up, as its description says. (This page is generated from",
        "`cloudsim/config.py`.)",
        "",
        "| variable | default | meaning |",
        "| --- | --- | --- |",
    ]
    for name, setting in SETTINGS.items():
        default = f"`{setting.default}`" if setting.default else "—"
        lines.append(f"| `{name}` | {default} | {_cell(setting.help)} |")
    lines += [
        "",
        "Keep `instance/encryption.key` (or `CLOUDSIM_ENCRYPTION_KEYS`) safe and backed up with",
        "the database: without it the stored SSH keys, VPN keys and cloud credentials cannot be",
        "read. To rotate, put a new key first in `CLOUDSIM_ENCRYPTION_KEYS` and keep the old one",
        "after it.",
        "",
    ]
    return "\n".join(lines)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def openapi_document() -> dict[str, Any]:
    """Return the OpenAPI document the app serves at /api/v1/openapi.json."""
    from cloudsim.app import create_app
    from cloudsim.config import Config

    with tempfile.TemporaryDirectory(prefix="cloudsim-docs-") as instance:
        app = create_app(Config.from_env({"CLOUDSIM_INSTANCE_DIR": instance}))
        response = app.test_client().get("/api/v1/openapi.json")
        assert response.status_code == 200, response.status
        spec: dict[str, Any] = response.get_json()
        with app.app_context():
            app.extensions["sqlalchemy"].engine.dispose()  # the folder goes: close its database
    return spec


def api_page(spec: dict[str, Any]) -> str:
    """Return every API operation: method, path, what it does, its body and answers."""
    lines = [
        f"# REST API ({spec['info'].get('version', '')})",
        "",
        "Every operation of `/api/v1`, from the OpenAPI document the server itself serves at",
        "`GET /api/v1/openapi.json` ([a copy of it](openapi.json)). Calls carry an API token",
        "(`Authorization: Bearer cst_...`, made on the Account page); the server checks role",
        "and team on every call, and another team's object answers exactly like a missing one",
        "(404).",
        "",
    ]
    by_tag: dict[str, list[str]] = {}
    for path, operations in spec.get("paths", {}).items():
        for method, op in operations.items():
            if method not in {"get", "post", "put", "patch", "delete"}:
                continue
            tag = (op.get("tags") or ["other"])[0]
            by_tag.setdefault(tag, []).extend(_operation(method, path, op))
    for tag in sorted(by_tag):
        lines += [f"## {tag}", "", *by_tag[tag]]
    return "\n".join(lines)


def _operation(method: str, path: str, op: dict[str, Any]) -> list[str]:
    lines = [f"### `{method.upper()} {path}`", ""]
    summary = op.get("summary") or op.get("description") or ""
    if summary:
        lines += [summary.strip(), ""]
    params = [p for p in op.get("parameters", []) if isinstance(p, dict) and "name" in p]
    if params:
        names = ", ".join(f"`{p['name']}` ({p.get('in', '')})" for p in params)
        lines += [f"Parameters: {names}.", ""]
    body = op.get("requestBody", {}).get("content", {}).get("application/json", {})
    if body:
        lines += [f"Body: {_schema_name(body.get('schema', {}))}.", ""]
    answers = ", ".join(
        f"{code} {_schema_name(_json_schema(answer))}".rstrip()
        for code, answer in op.get("responses", {}).items()
    )
    lines += [f"Answers: {answers}.", ""]
    return lines


def _json_schema(answer: dict[str, Any]) -> dict[str, Any]:
    schema: dict[str, Any] = answer.get("content", {}).get("application/json", {}).get("schema", {})
    return schema


def _schema_name(schema: dict[str, Any]) -> str:
    if "$ref" in schema:
        return "`" + schema["$ref"].rsplit("/", 1)[-1] + "`"
    if schema.get("type") == "array":
        return f"a list of {_schema_name(schema.get('items', {}))}"
    return ""


def on_page_markdown(markdown: str, **_: Any) -> str:
    """Put the code's own table of error codes where a page asks for it."""
    if ERROR_CODES_TABLE not in markdown:
        return markdown
    from cloudsim.error_codes import markdown_table

    return markdown.replace(ERROR_CODES_TABLE, markdown_table())
