"""Launch and terminate constellations: the bodies of their jobs, every stage idempotent.

A launch goes through keys, network, machines, firewall, install, verify and ready. Each
stage reads what already exists (in the database and at the provider) and only adds what is
missing, so a job resumed after its worker died finishes the work without duplicating or
leaking machines.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from flask import current_app
from libcloud.common.types import LibcloudError
from libcloud.compute.base import Node, NodeAuthSSHKey
from libcloud.compute.types import NodeState

from cloudsim.auth.policy import SYSTEM
from cloudsim.config import Config
from cloudsim.error_codes import LAUNCH_FAILED, LAUNCH_PROVIDER, LAUNCH_UNREACHABLE
from cloudsim.errors import CloudSimError
from cloudsim.extensions import db
from cloudsim.jobs.control import JobCancelled, cancel_jobs, wait_until_stopped
from cloudsim.jobs.runner import JobContext, job_kind
from cloudsim.launched_constellations import lifecycle
from cloudsim.launched_constellations.access import TEAM_KINDS, refresh_turn, team_members
from cloudsim.launched_constellations.connect import (
    forget_connections,
    machine_host_keys,
    record_routes,
    target_name,
    targets,
)
from cloudsim.launched_constellations.keys import (
    SSH_KEY_NAME,
    KeyPair,
    constellation_keypair,
    constellation_secret,
)
from cloudsim.launched_constellations.lifecycle import ConstellationJob
from cloudsim.launched_constellations.service import launched_kind
from cloudsim.launched_constellations.software import Supply, preinstall, supply_needs
from cloudsim.launched_constellations.verify import VerificationFailed, verify_constellation
from cloudsim.models import Constellation, ConstellationState, Secret, SecretKind
from cloudsim.models.machines import GONE
from cloudsim.providers.service import Provider, open_provider
from constellations.definition import ConstellationKind
from constellations.plans import (
    PLANS,
    Need,
    PlanContext,
    PlanItem,
    apply_plan,
    firewall,
    needs_of,
)
from constellations.plans.base import MemberAccount
from constellations.plans.members import member_accounts
from provisioners.providers.base import WAITING, CloudSimNodeDriver
from provisioners.providers.errors import ProviderError
from provisioners.remote.ssh import ConnectPolicy, SSHError, SSHExecutor, SSHTarget

T = TypeVar("T")
# how long a terminate waits for the constellation's other jobs to stop (they check their
# cancel flag every second while they talk to machines; making a machine is one step)
STOP_WAIT_SECONDS = 120


class ProvisioningError(CloudSimError):
    """A stage of a launch or terminate failed; the message says which and why."""


@job_kind("constellation.launch", payload=ConstellationJob)
def launch_constellation(ctx: JobContext, job: ConstellationJob) -> None:
    """Bring a constellation to `ready`, or to `error` with the reason."""
    constellation = ctx.load(Constellation, job.constellation_id)
    if constellation.state in GONE:
        raise ProvisioningError(f"{constellation.name} is {constellation.state.value}")
    config: Config = current_app.config["CLOUDSIM"]
    kind = launched_kind(constellation)
    lifecycle.launching(constellation)
    deployed = _team_access(constellation)  # the install below deploys these, or newer ones
    # kept in memory: a terminate that ends before this job stops deletes the stored key, and
    # what this job made since is reached (and cleaned) with it
    keys: KeyPair | None = None
    try:
        ctx.stage("keys", 2)
        keys = constellation_keypair(constellation)
        ctx.checkpoint()  # made once and kept before the provider is asked for anything
        _launch(ctx, constellation, kind, keys, config)
        ctx.check()  # the last step: a terminate asked before it wins
    except Exception as exc:
        db.session.rollback()
        if (reason := ctx.cancelled()) is not None:
            # the terminate owns the constellation now: write nothing, leave nothing behind
            ctx.log(f"stopped: {reason}")
            _release_if_terminated(ctx, job.constellation_id, config, keys)
            raise JobCancelled(f"cancelled: {reason}") from exc
        constellation = ctx.load(Constellation, job.constellation_id)
        if lifecycle.failed(
            constellation, ctx.masked(f"{ctx.job.stage}: {exc}"), launch_error_code(exc)
        ):
            ctx.checkpoint()  # the error state survives the runner's rollback
        raise
    ctx.stage("ready", 100)
    lifecycle.ready(constellation)
    ctx.checkpoint()  # ready first (unless cancelled): a change from now on starts its own push
    if constellation.kind in TEAM_KINDS and _team_access(constellation) != deployed:
        # changed while launching, when no push runs: the field computers have the old ones
        ctx.log("the team's members, keys or sudo changed during the launch: pushing them again")
        lifecycle.start_refresh_access(SYSTEM, constellation)


def launch_error_code(exc: BaseException) -> str:
    """Return the stable code of why a launch failed (cloudsim.error_codes)."""
    if isinstance(exc, VerificationFailed):
        return exc.code
    if isinstance(exc, SSHError):
        return LAUNCH_UNREACHABLE
    if isinstance(exc, LibcloudError | ProviderError):
        return LAUNCH_PROVIDER
    return LAUNCH_FAILED


def _release_if_terminated(
    ctx: JobContext, constellation_id: int, config: Config, keys: KeyPair | None
) -> None:
    """Release what a cancelled launch made when the terminate finished before it stopped
    (it did not wait long enough): its machines and network must not outlive it."""
    db.session.expire_all()
    constellation = ctx.load(Constellation, constellation_id)
    if constellation.state != ConstellationState.TERMINATED:
        return  # the terminate job still runs: it releases everything once this job ends
    provider = open_provider(constellation.provider, config)
    release_made_since(ctx, constellation, provider, keys, config)
    # not ctx.checkpoint(), which refuses a cancelled job's changes: this is the terminate's
    # own outcome (an incomplete release), which must survive the runner's rollback
    db.session.commit()


def release_made_since(
    ctx: JobContext,
    constellation: Constellation,
    provider: Provider,
    keys: KeyPair | None,
    config: Config,
) -> None:
    """Clean and release the machines and network of a terminated constellation that a
    cancelled launch made after its terminate ended, as the terminate does: each machine
    through its stored route with the launch's key (the terminate deleted the stored one).

    A machine not cleaned turns the constellation `terminate_incomplete` with the reason,
    and the key is stored again, so that the retry of terminate reaches it.
    """
    nodes = provider.nodes(constellation.name)
    if not nodes:
        not_cleaned: dict[str, str] = {}
    elif keys is None:
        # this job stopped before it had the key, so it made none of them: nothing reaches them
        not_cleaned = {node.name: "no key to reach it" for node in nodes}
    else:
        not_cleaned = _destroy_machines(
            ctx, constellation, provider, nodes, config, keys, db.session.commit
        )
    if not_cleaned:
        reason = ctx.masked("; ".join(f"{n}: {why}" for n, why in sorted(not_cleaned.items())))
        if keys is not None:
            private = keys.private
            constellation_secret(
                constellation, SSH_KEY_NAME, SecretKind.SSH_PRIVATE_KEY, lambda: private
            )
        lifecycle.terminate_incomplete(constellation, reason)
        ctx.log(f"the terminate had already ended; what was made since is not released: {reason}")
        return
    driver = provider.driver
    network = {n.name: n for n in driver.ex_list_networks()}.get(constellation.name)
    if network is not None:
        driver.ex_destroy_network(network)
        ctx.log(f"destroyed network {network.name}")
    ctx.log(f"the terminate had already ended: released {len(nodes)} machine(s) made since")


def _team_access(constellation: Constellation) -> tuple[tuple[MemberAccount, ...], bool]:
    """Return what the field computers get: the members' accounts and keys, and sudo or not."""
    return team_members(constellation.team_id), constellation.team_sudo


def _launch(
    ctx: JobContext,
    constellation: Constellation,
    kind: ConstellationKind,
    keys: KeyPair,
    config: Config,
) -> None:
    provider = open_provider(constellation.provider, config)
    driver = provider.driver
    ctx.stage("network", 5)
    subnet = ensure_network(ctx, driver, constellation, kind)
    ctx.stage("machines", 10)
    for change in driver.ex_prepare():
        ctx.log(f"raised the hosts' shared kernel limit {change}")
    preinstall(ctx.log, driver, kind, config)
    nodes = ensure_machines(ctx, provider, constellation, kind, keys, subnet)
    record_routes(constellation, provider, nodes)
    ctx.checkpoint()
    executor = SSHExecutor(
        machine_host_keys(constellation),
        log_sink=ctx.line_sink(),
        secrets=[keys.private],
        connect_policy=ConnectPolicy(deadline=120),
        interrupt=ctx.interrupted,
    )
    with executor:
        reach = targets(constellation, keys, config)
        contexts = {
            m.name: _plan_context(constellation, kind, m.name, subnet, config)
            for m in kind.machines
        }
        ctx.stage("firewall", 40)
        driver.ex_apply_firewall(
            driver.ex_get_network(constellation.name), kind.firewall, kind.roles
        )
        _deploy(ctx, executor, reach, {n: firewall(c) for n, c in contexts.items()})
        ctx.stage("install", 50)
        contexts = supply_needs(Supply(ctx, executor, constellation, config), contexts)
        plans = {
            n: [item for plan in c.machine.plan for item in PLANS[plan](c)]
            for n, c in contexts.items()
        }
        _deploy(ctx, executor, reach, plans)
        ctx.stage("verify", 80)
        verify_constellation(
            ctx,
            executor,
            constellation,
            kind,
            reach,
            driver.ex_public_proxy_command,
            driver.ex_public_command,
            config.verify_retry_seconds,
            config.sim_min_rtf,
        )


@job_kind("constellation.refresh_access", payload=ConstellationJob)
def refresh_access(ctx: JobContext, job: ConstellationJob) -> None:
    """Push who may come in: the VPN's revocations to the router (ending the revoked sessions
    only) and the members' accounts and keys to the field computers (ending former members').

    One at a time per constellation; each reads the members once it is its turn."""
    with refresh_turn(job.constellation_id):
        _refresh_access(ctx, job)


def _refresh_access(ctx: JobContext, job: ConstellationJob) -> None:
    constellation = ctx.load(Constellation, job.constellation_id)
    if constellation.state != ConstellationState.READY:
        ctx.log(
            f"{constellation.name} is {constellation.state.value}: its next launch "
            "applies the current keys and revocation list"
        )
        return
    config: Config = current_app.config["CLOUDSIM"]
    kind = launched_kind(constellation)
    # the machines whose plans deploy the VPN (just those plans), and the field computers
    routers = [m for m in kind.machines if Need.VPN in needs_of(m.plan)]
    field_computers = [m for m in kind.machines if "field_computer" in m.plan]
    keys = constellation_keypair(constellation)
    subnet = constellation.resources["subnet"]
    with SSHExecutor(
        machine_host_keys(constellation),
        log_sink=ctx.line_sink(),
        secrets=[keys.private],
        interrupt=ctx.interrupted,
    ) as executor:
        reach = targets(constellation, keys, config)
        contexts = {
            m.name: _plan_context(constellation, kind, m.name, subnet, config) for m in routers
        }
        ctx.stage("access", 30)
        contexts = supply_needs(Supply(ctx, executor, constellation, config), contexts)
        plans = {
            n: [item for p in c.machine.plan if Need.VPN in needs_of([p]) for item in PLANS[p](c)]
            for n, c in contexts.items()
        }
        members: tuple[MemberAccount, ...] = ()
        for machine in field_computers:
            context = _plan_context(constellation, kind, machine.name, subnet, config)
            members = context.members
            plans[machine.name] = member_accounts(context)
        _deploy(ctx, executor, {n: reach[n] for n in plans}, plans)
        ctx.log(
            f"member accounts: {', '.join(m.name for m in members) or 'none'} "
            f"({sum(len(m.keys) for m in members)} key(s))"
        )


def ensure_network(
    ctx: JobContext,
    driver: CloudSimNodeDriver,
    constellation: Constellation,
    kind: ConstellationKind,
) -> str:
    """Create the private network once; return its subnet."""
    existing = {n.name: n for n in driver.ex_list_networks()}
    network = existing.get(constellation.name)
    if network is None:
        network = driver.ex_create_network(constellation.name)
        ctx.log(f"created network {network.name} ({network.cidr})")
    else:
        ctx.log(f"network {network.name} ({network.cidr}) exists")
    constellation.resources = {
        **constellation.resources,
        "network": network.name,
        "subnet": network.cidr,
    }
    for machine in constellation.machines:
        machine.private_ip = kind.machine(machine.name).address(network.cidr)
    ctx.checkpoint()
    return str(network.cidr)


def ensure_machines(
    ctx: JobContext,
    provider: Provider,
    constellation: Constellation,
    kind: ConstellationKind,
    keys: KeyPair,
    subnet: str,
) -> list[Node]:
    """Create every machine the provider does not have running; replace broken ones."""
    driver = provider.driver
    network = driver.ex_get_network(constellation.name)
    have = {
        node.extra["tags"].get("cloudsim:machine"): node
        for node in provider.nodes(constellation.name)
    }
    wanted = list(kind.machines)
    for definition in wanted:
        node = have.get(definition.name)
        if node is not None and node.state in WAITING:
            ctx.log(f"{definition.name}: still {node.state}; waiting for it")
            have[definition.name] = driver.wait_until_running([node])[0][0]
        elif node is not None and node.state != NodeState.RUNNING:
            ctx.log(f"{definition.name}: found {node.state}; replacing it")
            driver.destroy_node(node)
            del have[definition.name]
    missing = [m for m in wanted if m.name not in have]
    rows = {m.name: m for m in constellation.machines}
    for definition in missing:
        lifecycle.machine_creating(rows[definition.name])
    ctx.checkpoint()
    image = provider.image()
    sizes = {m.name: provider.size(m.size) for m in missing}
    name = constellation.name  # plain values only: the threads have no database session

    def create(definition: Any) -> Node:
        return driver.create_node(
            name=f"{name}-{definition.name}",
            size=sizes[definition.name],
            image=image,
            auth=NodeAuthSSHKey(keys.public),
            ex_network=network,
            ex_private_ip=definition.address(subnet),
            ex_public=definition.public,
            ex_tags={
                "cloudsim:constellation": name,
                "cloudsim:machine": definition.name,
                "cloudsim:role": definition.role,
            },
        )

    created = _in_parallel(missing, create, lambda d: d.name)
    log = ctx.line_sink()
    for name, node in created.items():
        log(name, f"created {node.id} ({', '.join(node.private_ips + node.public_ips)})")
    nodes = {**have, **created}
    for name, node in nodes.items():
        row = rows[name]
        row.provider_node_id = str(node.id)
        row.public_ip = node.public_ips[0] if node.public_ips else None
        # Providers of existing machines (servers) decide the address; clouds honour ours.
        row.private_ip = node.private_ips[0] if node.private_ips else row.private_ip
        lifecycle.machine_running(row)
    ctx.checkpoint()
    return list(nodes.values())


def _in_parallel(
    items: Sequence[Any], fn: Callable[[Any], T], key: Callable[[Any], str]
) -> dict[str, T]:
    """Call fn on every item in threads; raise one error naming every failure."""
    results, failures = _outcomes(items, fn, key)
    if failures:
        raise ProvisioningError(
            "; ".join(f"{name}: {error}" for name, error in sorted(failures.items()))
        )
    return results


def _outcomes(
    items: Sequence[Any], fn: Callable[[Any], T], key: Callable[[Any], str]
) -> tuple[dict[str, T], dict[str, str]]:
    """Call fn on every item in threads; return the results and each failure's message."""
    from concurrent.futures import ThreadPoolExecutor

    if not items:
        return {}, {}
    with ThreadPoolExecutor(max_workers=len(items)) as pool:
        futures = {key(item): pool.submit(fn, item) for item in items}
    failures = {name: str(f.exception()) for name, f in futures.items() if f.exception()}
    results = {name: f.result() for name, f in futures.items() if name not in failures}
    return results, failures


def _plan_context(
    constellation: Constellation, kind: ConstellationKind, name: str, subnet: str, config: Config
) -> PlanContext:
    field_computer = "field_computer" in kind.machine(name).plan
    return PlanContext(
        constellation=constellation.name,
        team=constellation.team.name if constellation.team else "",
        kind=kind,
        machine=kind.machine(name),
        subnet=subnet,
        addresses={m.name: m.private_ip or "" for m in constellation.machines},
        members=team_members(constellation.team_id) if field_computer else (),
        team_sudo=constellation.team_sudo,
        sim_min_rtf=config.sim_min_rtf,
    )


def _deploy(
    ctx: JobContext,
    executor: SSHExecutor,
    reach: dict[str, SSHTarget],
    plans: dict[str, list[PlanItem]],
) -> None:
    """Apply each machine's plan, all machines at once; fail naming every machine that failed."""
    ctx.checkpoint()  # the machines' threads write the log while this waits

    def deploy(target: SSHTarget) -> int:
        return apply_plan(executor, target, plans[target.name.rsplit("/", 1)[-1]])

    try:
        outcome = executor.run_parallel(list(reach.values()), deploy)
    except SSHError as exc:
        raise ProvisioningError(str(exc)) from exc
    ctx.log(", ".join(f"{name.rsplit('/', 1)[-1]}: {n} changed" for name, n in outcome.items()))


@job_kind("constellation.terminate", payload=ConstellationJob)
def terminate_constellation(ctx: JobContext, job: ConstellationJob) -> None:
    """Release every resource of a constellation; safe to run again and again.

    A machine that cannot be cleaned keeps the constellation `terminate_incomplete`, with
    its key, network and routes, so that terminating again (the retry) can still reach it.
    """
    constellation = ctx.load(Constellation, job.constellation_id)
    config: Config = current_app.config["CLOUDSIM"]
    lifecycle.terminating(constellation)
    forget_connections(constellation)  # other processes' beats forget them on their own
    # a launch (or push) started before the terminate, or sent since: told to stop, and
    # waited for, so that what it makes up to its next step is released below
    cancel_jobs(
        "constellation",
        constellation.id,
        f"{constellation.name} is being terminated",
        keep=[lifecycle.TERMINATE_JOB],
    )
    ctx.checkpoint()
    ctx.stage("stopping its jobs", 5)
    still = wait_until_stopped(
        "constellation",
        constellation.id,
        STOP_WAIT_SECONDS,
        keep=[lifecycle.TERMINATE_JOB],
        besides=ctx.job.id,
        log=ctx.log,
    )
    if still:
        ctx.log(f"job(s) {', '.join(still)} still running: each releases what it makes later")
    ctx.stage("machines", 10)
    provider = open_provider(constellation.provider, config)
    driver = provider.driver
    nodes = provider.nodes(constellation.name)
    not_cleaned = _destroy_machines(
        ctx,
        constellation,
        provider,
        nodes,
        config,
        constellation_keypair(constellation),
        ctx.checkpoint,
    )
    forget_connections(constellation)
    if not_cleaned:
        reason = "; ".join(f"{name}: {why}" for name, why in sorted(not_cleaned.items()))
        lifecycle.terminate_incomplete(constellation, ctx.masked(reason))
        ctx.checkpoint()  # the incomplete state survives the runner's rollback
        raise ProvisioningError(f"terminate incomplete: {ctx.masked(reason)}")
    ctx.log(f"destroyed {len(nodes)} machine(s)")
    ctx.stage("network", 70)
    network = {n.name: n for n in driver.ex_list_networks()}.get(constellation.name)
    if network is not None:
        driver.ex_destroy_network(network)
        ctx.log(f"destroyed network {network.name}")
    ctx.stage("keys", 90)
    db.session.query(Secret).filter_by(
        owner_type="constellation", owner_id=constellation.id
    ).delete()
    lifecycle.terminated(constellation)
    ctx.stage("terminated", 100)


def _destroy_machines(
    ctx: JobContext,
    constellation: Constellation,
    provider: Provider,
    nodes: list[Node],
    config: Config,
    keys: KeyPair,
    commit: Callable[[], None],
) -> dict[str, str]:
    """Destroy the nodes, each cleaned through the route a launch uses; return machine -> why
    it is not destroyed.

    Machines reached through another (behind the router) go first: the router goes only once
    they are clean, since cleaning it closes the way to them.
    """
    if not nodes:
        return {}
    reach = targets(constellation, keys, config)
    jumps = {t.jump.name for t in reach.values() if t.jump is not None}

    def machine(node: Node) -> str:
        return str(node.extra.get("tags", {}).get("cloudsim:machine", node.name))

    behind = [n for n in nodes if target_name(constellation, machine(n)) not in jumps]
    gateways = [n for n in nodes if target_name(constellation, machine(n)) in jumps]
    host_keys = machine_host_keys(constellation)
    commit()  # the machines' threads record host keys and log lines meanwhile
    executor = SSHExecutor(
        host_keys,
        log_sink=ctx.line_sink(),
        secrets=[keys.private],
        connect_policy=ConnectPolicy(deadline=60, attempt_timeout=10),
    )
    driver = provider.driver

    def destroy(node: Node) -> bool:
        target = reach.get(machine(node))
        if target is None:
            return bool(driver.destroy_node(node))
        return bool(driver.ex_destroy_node_through(node, executor, target))

    with executor:
        _, failures = _outcomes(behind, destroy, machine)
        if failures:
            kept = "kept, so that the retry reaches the others through it"
            return {**failures, **{machine(node): kept for node in gateways}}
        _, failures = _outcomes(gateways, destroy, machine)
    return failures
