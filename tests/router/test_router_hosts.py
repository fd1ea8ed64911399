"""The router on real local hosts: VPN, latency, accounting, caps, log, isolation, faults.

Tests run in file order on one lab (booting it is the expensive part); each arms its own run.
"""

from __future__ import annotations

import json
import re

from tests.router.conftest import RouterLab, wait_for

LATENCY_MS = 250
PORT = 5005


def test_applying_the_router_plan_again_changes_nothing(lab: RouterLab) -> None:
    assert lab.apply_router(lab.vpn_material(revoked=[])) == 0
    status = lab.csrouter("status")
    assert status["daemon"] == "running" and status["healthy"], status
    assert lab.run("router", "stat -c %a /etc/openvpn/server/cloudsim/server.key").strip() == "600"


def test_only_root_controls_csrouter_and_arguments_are_checked(lab: RouterLab) -> None:
    assert lab.run("router", "stat -c %a /run/csrouter /run/csrouter/control.sock").split() == [
        "700",
        "600",
    ]
    as_nobody = lab.result("router", "setpriv --reuid=nobody --clear-groups csrouter status")
    assert as_nobody.exit_code == 3, as_nobody
    too_long = lab.result("router", "csrouter arm --latency-ms 2001")
    assert too_long.exit_code == 2 and "0-2000" in too_long.stderr


def test_round_trip_is_twice_the_latency(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", str(LATENCY_MS), "--run-id", "rtt")
    result = lab.result("ocu", f"ping -n -c 10 -i 0.2 -W 3 {lab.ip('sim')}", timeout=30)
    assert " 0% packet loss" in result.stdout, result.stdout
    rtts = sorted(float(ms) for ms in re.findall(r"time=([\d.]+) ms", result.stdout))
    # the median: one echo delayed by the loaded, shared test machine is not the router's doing
    assert 2 * LATENCY_MS <= rtts[0] and rtts[len(rtts) // 2] <= 2 * LATENCY_MS + 5, rtts
    # the other way round too: a flow the LAN starts towards the OCU
    result = lab.result("sim", f"ping -n -c 10 -i 0.2 -W 3 {ocu_address(lab)}", timeout=30)
    assert " 0% packet loss" in result.stdout, result.stdout
    rtts = sorted(float(ms) for ms in re.findall(r"time=([\d.]+) ms", result.stdout))
    assert 2 * LATENCY_MS <= rtts[0] and rtts[len(rtts) // 2] <= 2 * LATENCY_MS + 5, rtts


def ocu_address(lab: RouterLab) -> str:
    """Return the OCU's address inside the VPN."""
    return lab.run("ocu", "ip -4 -o addr show dev tun0").split()[3].split("/")[0]


def test_uplink_udp_payload_is_counted_exactly(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", str(LATENCY_MS), "--run-id", "count")
    out = lab.start_receiver("sim", PORT, timeout=20, idle=1.5)
    lab.send_udp("ocu", lab.ip("sim"), PORT, count=1000, size=1000, pps=2000)
    assert lab.received("sim", out) == {"datagrams": 1000, "bytes": 1_000_000}
    uplink = lab.csrouter("counters")["uplink"]
    assert uplink["accepted"]["payload_bytes"] == 1_000_000
    # 20 bytes of IPv4 and 8 of UDP header a datagram
    assert uplink["accepted"]["ip_bytes"] == 1_028_000
    assert uplink["accepted"]["packets"] == 1000 and uplink["dropped"]["packets"] == 0


def test_past_the_uplink_cap_the_sim_gets_exactly_what_fitted(lab: RouterLab) -> None:
    cap_bits = 8 * 1000 * 300 + 4000  # 300 datagrams and half of one more
    lab.csrouter(
        "arm", "--latency-ms", str(LATENCY_MS), "--uplink-bits", str(cap_bits), "--run-id", "up"
    )
    out = lab.start_receiver("sim", PORT, timeout=20, idle=1.5)
    lab.send_udp("ocu", lab.ip("sim"), PORT, count=500, size=1000, pps=2000)
    assert lab.received("sim", out) == {"datagrams": 300, "bytes": 300_000}
    uplink = lab.csrouter("counters")["uplink"]
    assert uplink["spent"] and uplink["remaining_bits"] == 4000 and uplink["spent_at"]
    assert uplink["dropped"]["payload_bytes"] == 200_000
    # once spent, even a packet that would fit is dropped until the next arm
    assert not lab.ping("ocu", lab.ip("sim")).ok


def test_past_the_downlink_cap_the_ocu_gets_exactly_what_fitted(lab: RouterLab) -> None:
    cap_bits = 8 * 700 * 250
    lab.csrouter(
        "arm", "--latency-ms", str(LATENCY_MS), "--downlink-bits", str(cap_bits), "--run-id", "down"
    )
    ocu_vpn = ocu_address(lab)
    out = lab.start_receiver("ocu", PORT, timeout=20, idle=1.5)
    lab.send_udp("sim", ocu_vpn, PORT, count=400, size=700, pps=2000)
    assert lab.received("ocu", out) == {"datagrams": 250, "bytes": 175_000}
    counters = lab.csrouter("counters")
    downlink = counters["downlink"]
    assert downlink["accepted"]["payload_bytes"] == 175_000 and downlink["remaining_bits"] == 0
    assert downlink["dropped"]["packets"] == 150 and downlink["spent"]
    assert counters["uplink"]["accepted"]["packets"] == 0


def test_the_bandwidth_log_has_a_line_a_second_per_direction(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", "20", "--run-id", "log")
    lab.ping("ocu", lab.ip("sim"), count=10)
    wait_for(lambda: lab.csrouter("counters")["elapsed_s"] >= 3.2, 10, "three seconds of run")
    final = lab.csrouter("disarm")
    path = lab.run("router", "csrouter log-path").strip()
    records = [json.loads(line) for line in lab.run("router", f"cat {path}").splitlines()]
    assert records[0]["event"] == "armed" and records[0]["run_id"] == "log"
    assert records[-1]["event"] == "disarmed"
    assert records[-1]["counters"]["uplink"] == final["uplink"]
    lines = [r for r in records if "direction" in r]
    seconds = int(final["elapsed_s"])
    for direction in ("uplink", "downlink"):
        mine = [r for r in lines if r["direction"] == direction]
        assert len(mine) == seconds, mine
        assert sum(r["bytes"] for r in mine) == mine[-1]["cumulative_bytes"] > 0
        assert all(r["cap_remaining_bits"] is None for r in mine)
    # ten pings of 56 data bytes: ICMP is charged its whole IP payload (64 bytes)
    assert final["uplink"]["accepted"]["payload_bytes"] == 640


def test_the_ocu_reaches_the_lan_and_nothing_else(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", "0", "--run-id", "isolation")
    assert lab.result("ocu", f"timeout 5 bash -c '</dev/tcp/{lab.ip('sim')}/22'").ok
    # the router's own services, on its LAN and on its tunnel address
    for address in (lab.ip("router"), "10.8.0.1"):
        assert not lab.result("ocu", f"timeout 3 bash -c '</dev/tcp/{address}/22'").ok
    # the internet through the router: a client that routes it into the tunnel anyway
    internet = lab.run("router", "ip -4 route show default").split()[2]
    lab.run("ocu", f"ip route replace {internet}/32 dev tun0")
    try:
        before = _drop_count(lab)
        assert not lab.ping("ocu", internet, count=2).ok
        assert _drop_count(lab) >= before + 2
    finally:
        lab.run("ocu", f"ip route del {internet}/32 dev tun0")


def _drop_count(lab: RouterLab) -> int:
    listing = lab.run("router", "iptables -w 10 -L CLOUDSIM-FWD -v -x -n")
    rows = [line.split() for line in listing.splitlines() if "tun+" in line and "DROP" in line]
    return sum(int(row[0]) for row in rows)


def test_without_the_daemon_ocu_traffic_stops_and_status_says_so(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", "0", "--run-id", "fault")
    assert lab.ping("ocu", lab.ip("sim")).ok
    lab.run("router", "systemctl stop csrouter")
    try:
        assert not lab.ping("ocu", lab.ip("sim"), count=3).ok
        down = lab.result("router", "csrouter status --json")
        assert down.exit_code == 3 and json.loads(down.stdout)["daemon"] == "down"
        assert "does not answer" in down.stderr
    finally:
        lab.run("router", "systemctl start csrouter")
    assert lab.csrouter("status")["healthy"]  # a clean stop resumes the run without a fault
    # killed outright: systemd restarts it; the run resumes but the fault is reported
    pid = lab.run("router", "systemctl show -p MainPID --value csrouter").strip()
    lab.run("router", f"kill -KILL {pid}")
    wait_for(lambda: lab.result("router", "csrouter status --json").exit_code == 4, 20, "a restart")
    status = json.loads(lab.run("router", "csrouter status --json", check=False))
    assert status["run_id"] == "fault" and "unclean exit" in status["faults"][0]
    assert lab.ping("ocu", lab.ip("sim")).ok
    lab.csrouter("arm", "--latency-ms", "0", "--run-id", "after-fault")
    assert lab.csrouter("status")["healthy"]


def test_missing_queue_rules_are_a_fault_that_a_restart_repairs(lab: RouterLab) -> None:
    lab.run("router", "iptables -w 10 -t raw -D PREROUTING -j CLOUDSIM-OCU")
    unhealthy = lab.result("router", "csrouter status --json")
    assert unhealthy.exit_code == 4
    assert "NFQUEUE rules missing" in json.loads(unhealthy.stdout)["faults"][0]
    lab.run("router", "systemctl restart csrouter")
    assert lab.csrouter("status")["healthy"]
    assert lab.result("router", "iptables -w 10 -t raw -C PREROUTING -j CLOUDSIM-OCU").ok


def test_revoking_someone_else_does_not_interrupt_a_connected_client(
    lab: RouterLab,
) -> None:
    lab.csrouter("arm", "--latency-ms", "0", "--run-id", "revoke-other")
    server_pid = lab.run("router", "systemctl show -p MainPID --value openvpn-server@cloudsim")
    address = lab.run("ocu", "ip -4 -o addr show dev tun0 | awk '{print $4}'")
    departed = lab.clients["departed"].serial
    assert lab.apply_router(lab.vpn_material(revoked=[departed])) > 0
    # no restart: the new list is read at the next handshake; the OCU keeps its session
    assert " 0% packet loss" in lab.ping("ocu", lab.ip("sim"), count=10, wait=1).stdout
    assert lab.run("router", "systemctl show -p MainPID --value openvpn-server@cloudsim") == (
        server_pid
    )
    assert lab.run("ocu", "ip -4 -o addr show dev tun0 | awk '{print $4}'") == address


def test_a_revoked_client_cannot_connect(lab: RouterLab) -> None:
    lab.csrouter("arm", "--latency-ms", "0", "--run-id", "revoke")
    revoked = lab.clients["ocu"].serial
    assert lab.apply_router(lab.vpn_material(revoked=[revoked, lab.clients["departed"].serial])) > 0
    # its session is ended over the management socket, with the reason, and the client stops
    client = "journalctl -u openvpn-client@ocu --no-pager -o cat"
    wait_for(
        lambda: "Halt command was pushed by server" in lab.run("ocu", client),
        30,
        "the client to be told to stop",
    )
    assert not lab.ping("ocu", lab.ip("sim"), count=3).ok
    # started again, the revocation list refuses it
    lab.run("ocu", "systemctl restart openvpn-client@ocu")
    journal = "journalctl -u openvpn-server@cloudsim --no-pager -o cat"
    wait_for(
        lambda: "certificate revoked" in lab.run("router", journal), 30, "the server to refuse"
    )
    assert not lab.ping("ocu", lab.ip("sim"), count=3).ok
    lab.stop_client("ocu")
    lab.start_client("spare")
    try:
        wait_for(lambda: lab.ping("ocu", lab.ip("sim")).ok, 30, "the spare client's tunnel")
    finally:
        lab.stop_client("spare")
