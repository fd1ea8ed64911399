"""Pages for world definitions: the list, one world's document, and the upload form."""

from __future__ import annotations

import json

from flask import Blueprint, flash, redirect, render_template, url_for
from flask.typing import ResponseReturnValue
from flask_login import current_user
from flask_wtf import FlaskForm
from flask_wtf.file import FileField
from wtforms import TextAreaField

from cloudsim.auth.policy import role_required
from cloudsim.errors import CloudSimError, InvalidInput
from cloudsim.extensions import db
from cloudsim.models import Role
from cloudsim.web.downloads import attachment
from cloudsim.web.inputs import uploaded_text
from cloudsim.worlds import service

bp = Blueprint("worlds", __name__)


class WorldUploadForm(FlaskForm):
    """A world document, as a file or pasted (JSON or YAML)."""

    file = FileField("World file (JSON or YAML)")
    text = TextAreaField("…or the document itself")

    def document_text(self) -> str:
        """Return the uploaded or pasted text."""
        return uploaded_text(
            self.file.data, self.text.data, service.MAX_DOCUMENT_BYTES, "a world document"
        )


def _index(form: WorldUploadForm, status: int = 200) -> ResponseReturnValue:
    return render_template("worlds/index.html", worlds=service.stored_worlds(), form=form), status


@bp.route("/worlds")
@role_required(Role.ADMIN)
def index() -> ResponseReturnValue:
    return _index(WorldUploadForm())


@bp.route("/worlds", methods=["POST"])
@role_required(Role.ADMIN)
def upload() -> ResponseReturnValue:
    form = WorldUploadForm()
    if not form.validate_on_submit():
        return _index(form, 400)
    try:
        text = form.document_text()
        if not text.strip():
            raise InvalidInput("choose a world file or paste its document")
        done = service.update_world(current_user, service.parse_document(text))
    except CloudSimError as exc:
        db.session.rollback()
        form.form_errors.append(str(exc))
        return _index(form, exc.status)
    world = done.world
    if done.changed:
        flash(f"{world.name} is now version {world.version}; team instances follow.", "info")
    else:
        flash(f"{world.name} already had this document (version {world.version}).", "info")
    return redirect(url_for("worlds.show", name=world.name))


@bp.route("/worlds/<name>")
@role_required(Role.ADMIN)
def show(name: str) -> ResponseReturnValue:
    world = service.get_world(current_user, name)
    return render_template(
        "worlds/show.html", world=world, text=json.dumps(world.document, indent=2)
    )


@bp.route("/worlds/<name>.json")
@role_required(Role.ADMIN)
def download(name: str) -> ResponseReturnValue:
    world = service.get_world(current_user, name)
    return attachment(
        json.dumps(world.document, indent=2) + "\n", f"{world.name}.json", "application/json"
    )
