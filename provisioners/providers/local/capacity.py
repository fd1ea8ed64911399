"""How many more hosts this machine can take, and the kernel limits every host draws on.

All hosts share one kernel and, being root in the same user namespace, one set of per-user
limits: a storm of launches used to find them by failing (systemd in the 20th host: "Failed
to create inotify object"). The limits are raised once, within the kernel's own ceilings, to
what the machine's memory could hold in hosts; the capacity is the smallest of what threads,
those limits, a configured cap and the subnets left allow, and the memory left, each host
counted as its role's measured figure (host_memory.py).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

from provisioners.providers.capacity import Capacity, Demand
from provisioners.providers.local.host_memory import HostMemory, measured, uniform

log = logging.getLogger(__name__)

PROC_SYS = Path("/proc/sys")
MEMINFO = Path("/proc/meminfo")
LOADAVG = Path("/proc/loadavg")
MIB = 2**20


@dataclass(frozen=True)
class KernelLimit:
    """A sysctl every host draws on: what one host needs, what the rest of the machine keeps."""

    key: str
    per_host: int
    reserve: int
    ceiling: int  # the most this provider ever sets (the kernel's own maximum or below)

    def path(self, proc_sys: Path = PROC_SYS) -> Path:
        """Return the limit's file under /proc/sys."""
        return proc_sys / self.key.replace(".", "/")


# Per-host figures measured on a vrc storm with margin (a systemd host holds ~6 inotify
# instances and ~200 watches, ~40 threads); the team account's keyrings are one uid's on
# every field computer.
KERNEL_LIMITS = (
    KernelLimit("fs.inotify.max_user_instances", 16, 512, 1 << 20),
    KernelLimit("fs.inotify.max_user_watches", 2048, 65536, 1 << 24),
    KernelLimit("kernel.keys.maxkeys", 16, 200, 1 << 20),
    KernelLimit("kernel.keys.maxbytes", 16 * 1024, 20000, 1 << 30),
    KernelLimit("kernel.pid_max", 256, 32768, 4194304),  # PID_MAX_LIMIT on 64 bits
    KernelLimit("net.netfilter.nf_conntrack_max", 512, 65536, 1 << 22),
)
THREADS_PER_HOST = 64
THREADS_MAX = KernelLimit("kernel.threads-max", 0, 0, 0)  # only read: sized from memory


@dataclass(frozen=True)
class Budget:
    """What the operator configures: a cap on hosts, memory per host and kept back."""

    max_hosts: int = 0  # 0: no cap beyond what the machine allows
    host_memory_mib: int = 0  # 0: each role's measured figure (host_memory.json)
    memory_reserve_mib: int = 2048

    def figures(self) -> HostMemory:
        """Return what a host of each role counts: measured, unless the operator set one."""
        return uniform(self.host_memory_mib) if self.host_memory_mib else measured()


def meminfo(path: Path = MEMINFO) -> dict[str, int]:
    """Return /proc/meminfo's figures in bytes."""
    figures = {}
    for line in path.read_text().splitlines():
        name, _, rest = line.partition(":")
        number, *unit = rest.split()
        figures[name] = int(number) * (1024 if unit else 1)
    return figures


def memory_hosts(budget: Budget, memory: int) -> int:
    """Return how many of the smallest hosts fit in memory bytes, after the reserve (what the
    kernel limits are sized for)."""
    smallest = budget.figures().smallest() * MIB
    return max(0, (memory - budget.memory_reserve_mib * MIB) // smallest)


def read_limit(limit: KernelLimit, proc_sys: Path = PROC_SYS) -> int | None:
    """Return the limit's current value, None when this kernel has no such limit."""
    try:
        return int(limit.path(proc_sys).read_text().split()[0])
    except (FileNotFoundError, ValueError, IndexError):
        return None


def wanted_value(limit: KernelLimit, hosts: int) -> int:
    """Return the value the limit needs for hosts, within its ceiling."""
    return min(limit.ceiling, limit.reserve + limit.per_host * hosts)


def sized_hosts(budget: Budget) -> int:
    """Return the hosts the limits are sized for: what memory holds, at most the cap."""
    hosts = memory_hosts(budget, meminfo()["MemTotal"])
    return min(hosts, budget.max_hosts) if budget.max_hosts else hosts


def raise_limits(
    budget: Budget, limits: tuple[KernelLimit, ...] = KERNEL_LIMITS, proc_sys: Path = PROC_SYS
) -> list[str]:
    """Raise each limit below what sized_hosts need; return what changed.

    Idempotent: a limit at or above its wanted value (e.g. set higher by the operator) is left
    alone. A limit the kernel refuses (a read-only /proc/sys) is logged and counts as it is.
    """
    hosts = sized_hosts(budget)
    changed = []
    for limit in limits:
        current = read_limit(limit, proc_sys)
        wanted = wanted_value(limit, hosts)
        if current is None or current >= wanted:
            continue
        try:
            limit.path(proc_sys).write_text(f"{wanted}\n")
        except OSError as error:
            log.warning("cannot raise %s from %d to %d: %s", limit.key, current, wanted, error)
            continue
        changed.append(f"{limit.key} {current} -> {wanted}")
        log.info(
            "local provider: %s %d -> %d (sized for %d hosts)", limit.key, current, wanted, hosts
        )
    return changed


def host_bounds(
    budget: Budget, hosts_now: int, pending: int, limits: tuple[KernelLimit, ...] = KERNEL_LIMITS
) -> dict[str, int]:
    """Return, per resource, how many more hosts it allows beyond hosts_now and pending ones.

    Limits count as raise_limits leaves them (the next host created raises them).
    """
    committed = hosts_now + pending
    # the configured cap first: named as the limit when others allow exactly as many
    bounds = {"configured maximum": budget.max_hosts - committed} if budget.max_hosts else {}
    sized = sized_hosts(budget)
    raised = {}
    for limit in limits:
        current = read_limit(limit)
        if current is not None:
            raised[limit.key] = max(current, wanted_value(limit, sized))
            bounds[limit.key] = (raised[limit.key] - limit.reserve) // limit.per_host - committed
    # every thread takes a PID: both pid_max and threads-max bound the threads
    thread_limits = [raised.pop("kernel.pid_max", None), read_limit(THREADS_MAX)]
    bounds.pop("kernel.pid_max", None)
    usable = min(value for value in thread_limits if value is not None)
    bounds["threads"] = (usable - _threads_in_use()) // THREADS_PER_HOST - pending
    return {name: max(0, value) for name, value in bounds.items()}


def _threads_in_use() -> int:
    """Return the kernel's scheduling entities (threads), which draw on pid_max and threads-max."""
    return int(LOADAVG.read_text().split()[3].split("/")[1])


def memory_bounds(budget: Budget, roles_now: list[str], pending: Demand) -> dict[str, int]:
    """Return, per limit, the MiB left for more hosts beyond the existing and pending ones.

    Existing and pending hosts count as their role's figure against the machine's memory;
    against what is available now only pending ones (existing hosts already took theirs).
    """
    figures = budget.figures()
    pending_mib = sum(figures.of(role) for role in pending.roles)
    committed = sum(figures.of(role) for role in roles_now) + pending_mib
    memory = meminfo()
    reserve = budget.memory_reserve_mib
    bounds = {
        "memory": memory["MemTotal"] // MIB - reserve - committed,
        "memory available now": memory["MemAvailable"] // MIB - reserve - pending_mib,
    }
    return {name: max(0, value) for name, value in bounds.items()}


def capacity(
    budget: Budget, roles_now: list[str], free_networks: int, free_public: int, pending: Demand
) -> Capacity:
    """Return what this machine can still take, given existing hosts (their roles) and pending
    launches."""
    bounds = host_bounds(budget, len(roles_now), pending.hosts)
    limited_by = min(bounds, key=lambda name: bounds[name])
    memory = memory_bounds(budget, roles_now, pending)
    memory_limited_by = min(memory, key=lambda name: memory[name])
    figures = budget.figures()
    return Capacity(
        hosts=bounds[limited_by],
        networks=max(0, free_networks - pending.networks),
        public=max(0, free_public - pending.public),
        limited_by=limited_by,
        bounds=bounds,
        memory_mib=memory[memory_limited_by],
        memory_limited_by=memory_limited_by,
        host_memory_mib=dict(figures.roles_mib),
        default_host_memory_mib=figures.default_mib,
    )
