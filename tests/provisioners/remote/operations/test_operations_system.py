"""Packages, services, sysctl, iptables, users and authorized keys, from data."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path
from typing import TypeVar

import pytest

from provisioners.remote.facts import (
    AuthorizedKeysFact,
    AuthorizedKeysState,
    DebPackagesFact,
    Fact,
    IptablesChainFact,
    PathState,
    ServiceFact,
    ServiceState,
    SysctlFact,
    UserFact,
    UserState,
)
from provisioners.remote.operations import (
    Command,
    Operation,
    OperationError,
    Upload,
    authorized_key,
    deb_packages,
    iptables_chain,
    iptables_chain_exact,
    iptables_rule,
    service,
    sysctl,
    user,
)

T = TypeVar("T")
KEY = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIOJj8kvFrXnlIYn62uMUYf2Vh/RqvackyGkmHawXzklR cs@vrc"


def read_locally(fact: Fact[T]) -> T:
    """Run a read-only fact command in a local shell and parse it as apply() would."""
    done = subprocess.run(["sh", "-c", fact.command], capture_output=True, text=True, check=False)
    assert done.returncode in fact.ok_exit_codes, done.stderr
    return fact.parse(done.stdout, done.returncode)


def test_installed_packages_need_nothing_missing_ones_are_installed() -> None:
    operation = deb_packages(["socat", "openvpn"])
    assert operation.steps({"socat": "1.7.4.4-2", "openvpn": "2.6.3-1"}) == []
    assert operation.steps({"socat": "1.7.4.4-2", "openvpn": None}) == [
        Command("DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends openvpn")
    ]


def test_package_fact_parses_dpkg_query_and_reads_this_machine() -> None:
    fact = DebPackagesFact(("socat", "openvpn", "nano"))
    output = "socat\tii \t1.7.4.4-2\nopenvpn\trc \t2.6.3-1\n"
    assert fact.parse(output, 1) == {"socat": "1.7.4.4-2", "openvpn": None, "nano": None}
    here = read_locally(DebPackagesFact(("openssh-server", "cloudsim-no-such-package")))
    assert here["openssh-server"] is not None and here["cloudsim-no-such-package"] is None
    with pytest.raises(ValueError, match="not a Debian package name"):
        deb_packages(["socat; reboot"])


def test_systemd_service_already_enabled_and_running_needs_nothing() -> None:
    assert service("ssh").steps(ServiceState("systemd", "enabled", active=True)) == []
    assert service("ssh").steps(ServiceState("systemd", "static", active=True)) == []


def test_systemd_service_is_unmasked_enabled_and_started() -> None:
    assert service("openvpn@server").steps(ServiceState("systemd", "disabled", False)) == [
        Command("systemctl enable openvpn@server"),
        Command("systemctl start openvpn@server"),
    ]
    assert service("ssh").steps(ServiceState("systemd", "masked", False)) == [
        Command("systemctl unmask ssh"),
        Command("systemctl enable ssh"),
        Command("systemctl start ssh"),
    ]
    stopped = service("ssh", running=False, enabled=None)
    assert stopped.steps(ServiceState("systemd", "enabled", True)) == [
        Command("systemctl stop ssh")
    ]
    assert stopped.name == "service ssh (stopped)"


def test_service_without_systemd_uses_init_scripts() -> None:
    assert service("ssh").steps(ServiceState("sysv", "disabled", False)) == [
        Command("update-rc.d ssh defaults"),
        Command("service ssh start"),
    ]
    assert service("ssh").steps(ServiceState("sysv", "enabled", True)) == []


def test_service_fact_parses_both_init_systems() -> None:
    fact = ServiceFact("ssh")
    assert fact.parse("init=systemd\nenabled=enabled\nactive=active\n", 0) == ServiceState(
        "systemd", "enabled", True
    )
    missing = fact.parse("init=systemd\nenabled=\nactive=inactive\n", 0)
    assert (missing.enabled_state, missing.enabled, missing.active) == ("not-found", False, False)
    assert fact.parse("init=sysv\nenabled=disabled\nactive=inactive\n", 0).init == "sysv"
    # this controller runs no systemd: the probe must take the init-script path
    here = read_locally(ServiceFact("cloudsim-no-such-service"))
    assert (here.init, here.enabled, here.active) == ("sysv", False, False)
    with pytest.raises(ValueError):
        ServiceFact("-ssh")


def test_sysctl_right_now_and_persisted_needs_nothing() -> None:
    operation = sysctl({"net.ipv4.ip_forward": 1})
    (upload,) = operation.steps({"net.ipv4.ip_forward": "1"}, PathState.absent())
    assert isinstance(upload, Upload)
    assert upload.destination == "/etc/sysctl.d/60-cloudsim.conf"
    assert "net.ipv4.ip_forward = 1\n" in upload.content.decode()
    persisted = PathState("file", 0o644, "root", "root", sha256=upload.sha256)
    assert operation.steps({"net.ipv4.ip_forward": "1"}, persisted) == []


def test_sysctl_differing_value_is_set_at_runtime() -> None:
    operation = sysctl({"net.ipv4.ip_forward": 1}, persist_path=None)
    assert operation.steps({"net.ipv4.ip_forward": "0"}) == [
        Command("sysctl -w net.ipv4.ip_forward=1")
    ]
    # multi-value parameters print tab-separated: compared word by word
    rmem = sysctl({"net.ipv4.tcp_rmem": "4096 131072 6291456"}, persist_path=None)
    assert rmem.steps({"net.ipv4.tcp_rmem": "4096 131072 6291456"}) == []
    assert rmem.steps({"net.ipv4.tcp_rmem": "4096 87380 6291456"}) == [
        Command("sysctl -w 'net.ipv4.tcp_rmem=4096 131072 6291456'")
    ]
    with pytest.raises(OperationError, match=r"no parameter net\.ipv4\.nope"):
        sysctl({"net.ipv4.nope": 1}, persist_path=None).steps({"net.ipv4.nope": None})


def test_sysctl_fact_reads_this_kernel_without_changing_it() -> None:
    fact = SysctlFact(("kernel.ostype", "net.ipv4.tcp_rmem", "cloudsim.no.such.key"))
    values = read_locally(fact)
    assert values["kernel.ostype"] == "Linux"
    assert values["net.ipv4.tcp_rmem"] is not None and "\t" not in values["net.ipv4.tcp_rmem"]
    assert values["cloudsim.no.such.key"] is None
    with pytest.raises(ValueError):
        SysctlFact(("kernel.ostype; reboot",))


def test_iptables_rule_present_needs_nothing_absent_is_appended() -> None:
    masquerade = ["-s", "10.0.0.0/24", "-o", "eth0", "-j", "MASQUERADE"]
    operation = iptables_rule("POSTROUTING", masquerade, table="nat")
    assert operation.steps(True) == []
    assert operation.steps(False) == [
        Command("iptables -w 10 -t nat -A POSTROUTING -s 10.0.0.0/24 -o eth0 -j MASQUERADE")
    ]
    assert operation.facts[0].command == (
        "iptables -w 10 -t nat -C POSTROUTING -s 10.0.0.0/24 -o eth0 -j MASQUERADE"
    )
    comment = iptables_rule(
        "INPUT", ["-m", "comment", "--comment", "vpn in", "-j", "ACCEPT"], insert=True, ipv6=True
    )
    assert comment.steps(False) == [
        Command("ip6tables -w 10 -t filter -I INPUT -m comment --comment 'vpn in' -j ACCEPT")
    ]
    with pytest.raises(ValueError):
        iptables_rule("INPUT", ["-j", "ACCEPT"], table="nat;reboot")


def test_iptables_chain_is_created_when_missing() -> None:
    operation = iptables_chain("CLOUDSIM-LAN")
    assert operation.steps(True) == []
    assert operation.steps(False) == [Command("iptables -w 10 -t filter -N CLOUDSIM-LAN")]
    fact = IptablesChainFact("filter", "CLOUDSIM-LAN")
    assert fact.parse("INPUT\nFORWARD\nOUTPUT\nCLOUDSIM-LAN\n", 0) is True
    assert fact.parse("INPUT\nFORWARD\nOUTPUT\n", 0) is False


def test_user_absent_is_created_present_is_adjusted() -> None:
    operation = user("cloudsim", login_shell="/bin/bash", groups=["adm", "sudo"])
    assert operation.steps(None) == [
        Command("useradd --create-home --shell /bin/bash --groups adm,sudo cloudsim")
    ]
    right = UserState(
        "cloudsim",
        1001,
        1001,
        "/home/cloudsim",
        "/bin/bash",
        "cloudsim",
        ("cloudsim", "adm", "sudo"),
    )
    assert operation.steps(right) == []
    wrong = UserState(
        "cloudsim", 1001, 1001, "/home/cloudsim", "/bin/sh", "cloudsim", ("cloudsim", "adm")
    )
    assert operation.steps(wrong) == [
        Command("usermod --shell /bin/bash cloudsim"),
        Command("usermod --append --groups sudo cloudsim"),
    ]


def test_user_fact_parses_getent_and_reads_root() -> None:
    fact = UserFact("cloudsim")
    parsed = fact.parse(
        "cloudsim:x:1001:1001:CloudSim:/home/cloudsim:/bin/bash\ncloudsim\ncloudsim adm\n", 0
    )
    assert parsed == UserState(
        "cloudsim", 1001, 1001, "/home/cloudsim", "/bin/bash", "cloudsim", ("cloudsim", "adm")
    )
    assert fact.parse("", 0) is None
    root = read_locally(UserFact("root"))
    assert root is not None and (root.uid, root.group) == (0, "root")
    assert read_locally(UserFact("cloudsim-nobody")) is None


def test_authorized_key_present_with_options_needs_nothing() -> None:
    blob_line = 'from="10.0.0.0/8" ' + KEY.rsplit(" ", 1)[0] + " another-comment\n"
    state = AuthorizedKeysState("/root/.ssh/authorized_keys", "root", True, blob_line)
    assert authorized_key("root", KEY).steps(state) == []


def test_authorized_key_absent_is_appended_keeping_other_keys() -> None:
    other = "ssh-ed25519 AAAAC3NzaC1lZDI1NTE5AAAAIOtherKeyOtherKeyOtherKeyOtherKeyOtherKeyO x"
    state = AuthorizedKeysState("/home/cs/.ssh/authorized_keys", "cs", False, None)
    assert authorized_key("cs", KEY).steps(state) == [
        Command("mkdir -p -m 0700 /home/cs/.ssh && chown cs:cs /home/cs/.ssh"),
        Upload("/home/cs/.ssh/authorized_keys", (KEY + "\n").encode(), 0o600, "cs", "cs"),
    ]
    existing = AuthorizedKeysState("/home/cs/.ssh/authorized_keys", "cs", True, other)
    assert authorized_key("cs", KEY).steps(existing) == [
        Upload("/home/cs/.ssh/authorized_keys", f"{other}\n{KEY}\n".encode(), 0o600, "cs", "cs")
    ]


def test_authorized_keys_fact_reads_a_file(tmp_path: Path) -> None:
    keys = tmp_path / "keys dir" / "authorized_keys"
    keys.parent.mkdir()
    keys.write_text(KEY + "\n")
    state = read_locally(AuthorizedKeysFact("root", str(keys)))
    assert state == AuthorizedKeysState(str(keys), "root", True, KEY + "\n")
    absent = read_locally(AuthorizedKeysFact("root", str(tmp_path / "nowhere" / "keys")))
    assert (absent.directory_exists, absent.content) == (False, None)


def test_an_exact_chain_is_rewritten_in_one_go_only_when_it_differs() -> None:
    """In a network namespace of its own: an old, wider rule is taken out; then no change."""
    netns = f"cs-exact-{os.getpid()}"
    subprocess.run(["ip", "netns", "add", netns], check=True)
    try:

        def shell(command: str) -> subprocess.CompletedProcess[str]:
            return subprocess.run(
                ["ip", "netns", "exec", netns, "sh", "-c", command],
                capture_output=True,
                text=True,
                check=False,
            )

        def state(operation: Operation) -> object:
            fact = operation.facts[0]
            done = shell(fact.command)
            return fact.parse(done.stdout, done.returncode)

        ssh = ["!", "-s", "10.0.0.0/24", "-p", "tcp", "--dport", "22", "-j", "ACCEPT"]
        noted = ["-m", "comment", "--comment", "the team VPN", "-j", "ACCEPT"]
        rules = [ssh, noted, ["-j", "DROP"]]
        operation = iptables_chain_exact("CS-IN", rules)
        assert state(operation) is None  # no chain yet
        shell("iptables -N CS-IN && iptables -A CS-IN -s 10.0.0.0/24 -j ACCEPT")
        [step] = operation.steps(state(operation))
        assert isinstance(step, Command)
        assert shell(step.text).returncode == 0
        listing = shell("iptables -S CS-IN").stdout
        assert "-A CS-IN -s 10.0.0.0/24 -j ACCEPT" not in listing
        assert "! -s 10.0.0.0/24" in listing and "the team VPN" in listing
        assert operation.steps(state(operation)) == []
    finally:
        subprocess.run(["ip", "netns", "del", netns], check=False)
