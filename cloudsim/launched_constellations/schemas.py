"""Request and response schemas of the constellations API."""

from __future__ import annotations

from marshmallow import Schema, fields, validate

from cloudsim.jobs.schemas import JobSchema
from cloudsim.web.inputs import Id


class MachineSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    role = fields.Str()
    state = fields.Str()
    private_ip = fields.Str(allow_none=True)
    public_ip = fields.Str(allow_none=True)
    verification = fields.Dict()


class HeardMachineSchema(MachineSchema):
    heard = fields.Str(
        allow_none=True,
        metadata={
            "description": "when CloudSim last heard from it (ISO 8601): a running run's live "
            "reader, else its verification (then followed by ' (verification)')"
        },
    )


class ConstellationSchema(Schema):
    id = fields.Int()
    name = fields.Str()
    kind = fields.Str()
    provider = fields.Str()
    team_id = fields.Int(allow_none=True)
    state = fields.Str()
    error = fields.Str(allow_none=True)
    error_code = fields.Str(
        allow_none=True, metadata={"description": "the failure's stable code (docs/error-codes.md)"}
    )
    created_at = fields.DateTime()
    team_sudo = fields.Bool(
        metadata={"description": "May the team's members use sudo on the field computers"}
    )
    machines = fields.List(fields.Nested(MachineSchema))


class ConstellationStatusSchema(ConstellationSchema):
    job_kind = fields.Str(
        allow_none=True, metadata={"description": "its latest job: launch, retry, terminate"}
    )
    job_state = fields.Str(allow_none=True)
    step = fields.Str(allow_none=True, metadata={"description": "the latest job's current step"})
    step_since = fields.Str(
        allow_none=True, metadata={"description": "when it entered that step (ISO 8601)"}
    )
    machines = fields.List(fields.Nested(HeardMachineSchema))


class ConstellationUpdateSchema(Schema):
    team_sudo = fields.Bool(required=True)


class LaunchSchema(Schema):
    name = fields.Str(required=True, validate=validate.Length(min=1, max=24))
    kind = fields.Str(required=True, validate=validate.Length(min=1, max=32))
    provider = fields.Str(load_default="local", validate=validate.Length(min=1, max=32))
    team_id = Id(allow_none=True, load_default=None)


class LaunchedSchema(Schema):
    constellation = fields.Nested(ConstellationSchema)
    job = fields.Nested(JobSchema)


class VpnBundleQuerySchema(Schema):
    user_id = Id(metadata={"description": "Officers: whose bundle (default: yours)"})


class CapacityQuerySchema(Schema):
    provider = fields.Str(load_default="local", validate=validate.Length(min=1, max=32))


class CapacitySchema(Schema):
    provider = fields.Str()
    known = fields.Bool(metadata={"description": "False: the provider does not say"})
    hosts = fields.Int(allow_none=True, metadata={"description": "More machines it can take"})
    networks = fields.Int(allow_none=True, metadata={"description": "More private networks"})
    public_addresses = fields.Int(allow_none=True, metadata={"description": "More public ones"})
    limited_by = fields.Str(allow_none=True, metadata={"description": "The scarcest resource"})
    memory_mib = fields.Int(
        allow_none=True, metadata={"description": "Memory left for more machines (MiB)"}
    )
    host_memory_mib = fields.Dict(
        keys=fields.Str(),
        values=fields.Int(),
        metadata={"description": "The memory a machine of each role counts as (MiB)"},
    )
    kinds = fields.Dict(
        keys=fields.Str(),
        values=fields.Int(),
        metadata={"description": "How many more constellations of each kind fit"},
    )
