"""Render machine templates with Jinja2, strictly, naming file and line on errors."""

from __future__ import annotations

import traceback
from collections.abc import Mapping
from pathlib import Path

import jinja2

import templates
from provisioners.remote.operations.errors import TemplateError


class MachineTemplates:
    """The templates pushed to machines, rendered locally before upload."""

    def __init__(self, directory: Path | None = None) -> None:
        self.directory = directory or templates.folder("machines")
        self._environment = jinja2.Environment(
            loader=jinja2.FileSystemLoader(self.directory),
            undefined=jinja2.StrictUndefined,
            keep_trailing_newline=True,
            trim_blocks=True,
            lstrip_blocks=True,
            # configuration files, not HTML: escaping would corrupt them
            autoescape=jinja2.select_autoescape(enabled_extensions=("html", "xml")),
        )

    def render(self, name: str, context: Mapping[str, object]) -> str:
        """Render a template by its name under the directory, e.g. "common/motd.j2"."""
        path = self.directory / name
        try:
            template = self._environment.get_template(name)
            return template.render(context)
        except jinja2.TemplateNotFound as exc:
            raise TemplateError(str(path), None, f"not found under {self.directory}") from exc
        except jinja2.TemplateSyntaxError as exc:
            raise TemplateError(exc.filename or str(path), exc.lineno, exc.message or "") from exc
        except jinja2.TemplateError as exc:
            filename, line = _template_position(exc, str(path))
            raise TemplateError(filename, line, exc.message or str(exc)) from exc


def _template_position(exc: BaseException, default_file: str) -> tuple[str, int | None]:
    """Return the template file and line where a render error happened."""
    # Jinja rewrites tracebacks so that template frames carry the template's own file and line
    template_frames = [
        frame
        for frame in traceback.extract_tb(exc.__traceback__)
        if frame.name in ("top-level template code", "template") or frame.filename.endswith(".j2")
    ]
    if not template_frames:
        return default_file, None
    return template_frames[-1].filename, template_frames[-1].lineno
