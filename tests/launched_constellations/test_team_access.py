"""A team runs its own code, end to end on a local vrc constellation, the way the README says:
a key added in Chromium, the VPN bundle on a stock OpenVPN OCU, each member logging into
their own account through the VPN (`ssh alice-7@fc1`, never as a teammate), code copied into
the team's shared workspace between runs (no run's bits spent), editable by every member, and
started with nohup, the run started in the browser and scored by the team's process, the
logins named in the run's logs; the simulator sealed; a disabled member's processes killed
and account removed within seconds while a teammate's run on, and another team's keys that
never work; sudo once an officer allows it."""

from __future__ import annotations

import shlex
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from flask import Flask
from playwright.sync_api import Browser, expect

from cloudsim.auth.policy import SYSTEM
from cloudsim.competition.supervision import supervise_runs
from cloudsim.config import Config
from cloudsim.extensions import db
from cloudsim.launched_constellations import router_control, service
from cloudsim.launched_constellations.connect import machine_host_keys, targets
from cloudsim.launched_constellations.keys import constellation_keypair, generate_keypair
from cloudsim.models import Constellation, Job, JobState, Role, Run, RunState, User
from cloudsim.people.service import create_team, update_user
from constellations.plans.base import member_account_name
from constellations.plans.members import WORKSPACE
from provisioners.remote.ssh import SSHExecutor, SSHTarget
from tests.competition.support import hold_task_2_with_gate_1_near, open_task
from tests.competition.test_run_e2e import browser, live_url  # noqa: F401 (fixtures)
from tests.conftest import make_user, token_for
from tests.launched_constellations.conftest import finished
from tests.launched_constellations.test_local_vpn import _download, _ocus, connect
from tests.support.servers import wait_for
from tests.web.test_browser import log_in_page

# a launch, a run and some forty SSH logins over a VPN with a 500 ms round trip: on a busy
# two-core machine that outlasts the default 600 s
pytestmark = [pytest.mark.hosts, pytest.mark.browser, pytest.mark.timeout(1500)]
HERE = Path(__file__).parent
CONTROLLER = HERE.parents[1] / "simulator" / "drcsim" / "example_controller.py"
SSH = "ssh -o BatchMode=yes -o StrictHostKeyChecking=no -o ConnectTimeout=8"


def _access_jobs_done(constellation_id: int) -> bool:
    db.session.expire_all()
    jobs = db.session.scalars(
        db.select(Job).where(
            Job.kind == "constellation.refresh_access", Job.target_id == constellation_id
        )
    ).all()
    return bool(jobs) and all(job.state == JobState.SUCCEEDED for job in jobs)


def test_a_team_logs_in_deploys_its_code_and_scores_while_sim_stays_sealed(
    constellations_app: Flask,
    constellations_worker: None,
    constellations_config: Config,
    live_url: str,  # noqa: F811
    browser: Browser,  # noqa: F811
) -> None:
    team, rivals = create_team(SYSTEM, "Rovers"), create_team(SYSTEM, "Rivals")
    alice, bob = make_user(Role.USER, team), make_user(Role.USER, team)
    eve = make_user(Role.USER, rivals)
    account = {
        name: member_account_name(user.email, user.id)
        for name, user in (("alice", alice), ("bob", bob), ("eve", eve))
    }
    constellation, job = service.launch(
        SYSTEM, name="teamacc", kind="vrc", provider="local", team_id=team.id
    )
    done = finished(job.id)
    assert done.state == JobState.SUCCEEDED, f"{done.error}\n{done.log[-3000:]}"
    db.session.refresh(constellation)
    address = {m.name: m.private_ip for m in constellation.machines}
    fc1, sim = address["fc1"], address["sim"]

    # alice adds her key in Chromium, on her account page; bob and eve with the API
    keys = {name: generate_keypair(name) for name in ("alice", "bob", "eve")}
    page = browser.new_context().new_page()
    log_in_page(page, live_url, alice)
    page.goto(f"{live_url}/account")
    page.get_by_label("Public key").fill(keys["alice"].public)
    page.get_by_role("button", name="Add key").click()
    expect(page.get_by_text("SHA256:").first).to_be_visible()
    # the constellation's page: how to log in, and the seal's allow and deny rows
    page.goto(f"{live_url}/constellations/{constellation.id}")
    expect(page.locator("#team-login + p")).to_contain_text(f"ssh {account['alice']}@{fc1}")
    expect(page.locator("#ssh-config")).to_contain_text(f"User {account['alice']}")
    machines = page.locator("#machines")
    for row in ("fc1 → sim:22 closed", "fc1 → sim:7700 open", "vpn → sim:22 closed"):
        expect(machines).to_contain_text(row)
    expect(machines).to_contain_text("vpn → fc1:22 open")
    client = constellations_app.test_client()
    for name, user in (("bob", bob), ("eve", eve)):
        added = client.post(
            "/api/v1/me/ssh-keys", json={"public_key": keys[name].public}, headers=token_for(user)
        )
        assert added.status_code == 201, added.get_json()
    wait_for(lambda: _access_jobs_done(constellation.id), 120, "the keys on the field computers")

    config = _download(constellations_app, alice, constellation.id)
    executor, (ocu,) = _ocus(constellations_config, ["ocu"])
    with executor:
        assert connect(executor, ocu, config, fc1) >= 400  # 250 ms each way
        for name, pair in keys.items():
            executor.put_file(ocu, pair.private.encode(), f"/root/{name}.key", mode=0o600)

        def as_team(
            key: str, command: str, host: str = fc1, login: str | None = None
        ) -> tuple[bool, str]:
            """Run a command on a field computer as the key's owner (or as `login`), from the
            OCU, over the VPN."""
            user = login or account[key]
            ssh = f"{SSH} -i /root/{key}.key {user}@{host} {shlex.quote(command)}"
            result = executor.run(ocu, ssh, check=False, timeout=60)
            return result.ok, result.stdout + result.stderr

        ok, whoami = as_team("alice", "id -un; id -gn; id -Gn")
        assert ok and whoami.split()[:2] == [account["alice"], "team"], whoami
        assert "sudo" not in whoami
        # each key logs into its owner's account only: not a teammate's, not the old shared one
        assert not as_team("alice", "true", login=account["bob"])[0]
        assert not as_team("bob", "true", login=account["alice"])[0]
        assert not as_team("alice", "true", login="team")[0]
        # the workspace is shared: what alice writes there bob may edit, and the other way
        ok, out = as_team(
            "alice", f"echo alice > {WORKSPACE}/notes.txt; stat -c '%a %G' ~/team/notes.txt"
        )
        assert ok and out.split() == ["664", "team"], out
        ok, out = as_team("bob", f"echo bob >> {WORKSPACE}/notes.txt && cat ~/team/notes.txt")
        assert ok and out.split() == ["alice", "bob"], out
        # nothing of a teammate's own home is readable
        ok, out = as_team("alice", f"ls /home/{account['bob']}")
        assert not ok and "Permission denied" in out, out

        # between runs: copy the code; the last run's counts do not move, no run is armed
        with router_of(constellations_config, constellation) as (router_exec, router):
            router_control.arm(router_exec, router, router_control.Limits(250, 10**6, 10**7), "r0")
            router_control.disarm(router_exec, router)
            before = router_control.counters(router_exec, router)
            executor.put_file(ocu, CONTROLLER, "/root/example_controller.py")
            executor.put_file(ocu, HERE / "team_code.py", "/root/team_code.py")
            copy = (
                f"scp -o BatchMode=yes -o StrictHostKeyChecking=no -i /root/alice.key "
                f"/root/example_controller.py /root/team_code.py {account['alice']}@{fc1}:team/"
            )
            executor.run(ocu, copy, timeout=60)
            after = router_control.counters(router_exec, router)
        assert not after["armed"] and after["last_run"] == before["last_run"]
        assert before["last_run"]["uplink"]["accepted"]["payload_bytes"] < 10_000
        # the team's process waits for the run, then drives the robot
        ok, _ = as_team(
            "alice", "cd team; nohup /opt/drcsim/bin/python team_code.py > team_code.log 2>&1 &"
        )
        assert ok

        # the simulator is sealed: SSH refused from the OCU and from fc1, its API is not
        assert not reaches(executor, ocu, sim, 22)
        assert reaches(executor, ocu, sim, 7700)
        probe = "timeout 3 bash -c {}; echo exit=$?"
        ok, out = as_team("alice", probe.format(shlex.quote(f"exec 3<>/dev/tcp/{sim}/22")))
        assert "exit=124" in out, out  # dropped: timed out
        ok, out = as_team("alice", probe.format(shlex.quote(f"exec 3<>/dev/tcp/{sim}/7700")))
        assert "exit=124" not in out, out  # reached (refused or accepted)
        # nothing of CloudSim's is readable; no sudo
        for secret in ("/root/.ssh/authorized_keys", "/etc/ssh/ssh_host_ed25519_key"):
            ok, out = as_team("alice", f"cat {secret}")
            assert not ok and "Permission denied" in out, out
        assert not as_team("alice", "sudo -n true")[0]
        # another team's key never works
        assert not as_team("eve", "true")[0]

        # alice starts the run in the browser; her process scores (at ~7.5 s: gate_1 moved to
        # 1.5 m in the world CloudSim holds; at its 4 m, ~16 s, the run had to last 25 s)
        hold_task_2_with_gate_1_near()
        task = open_task(team.id, timeout_s=15, latency_ms=250)
        page.goto(f"{live_url}/tasks")
        page.get_by_role("button", name="Start run").click()
        expect(page.locator("#run-state")).to_have_text("running", timeout=120_000)
        run = db.session.scalars(db.select(Run).where(Run.task_id == task.id)).one()
        ok, current = as_team("alice", "cat /var/lib/cloudsim/current-run.json")
        assert ok and f'"run_id": {run.id}' in current, current

        def beat(check: Callable[[Run], bool]) -> Callable[[], bool]:
            def ready() -> bool:
                supervise_runs()
                db.session.expire_all()
                return check(db.session.get(Run, run.id))  # type: ignore[arg-type]

            return ready

        wait_for(beat(lambda r: r.state in (RunState.FINISHED, RunState.ERROR)), 240, "the run")
        db.session.refresh(run)
        assert run.state == RunState.FINISHED and run.score >= 1, (run.error, run.score)
        ok, log = as_team("alice", "cat team/team_code.log")
        assert f'"run_id": {run.id}' in log, log
        assert not as_team("alice", "test -e /var/lib/cloudsim/current-run.json")[0]

        # the run's logs say who logged into the field computers, by member
        _logins_are_in_the_run_s_logs(constellations_app, run, alice, account["alice"])

        # bob is disabled: his key stops, his running process is killed and his account goes
        # within seconds; alice's process and the files bob left in the workspace stay
        pids = {}
        for name in ("alice", "bob"):
            ok, out = as_team(name, "nohup sleep 3600 > /dev/null 2>&1 & echo $!")
            assert ok, out
            pids[name] = int(out.split()[-1])
        alive = "test -d /proc/{} && echo alive || echo gone"
        assert as_team("alice", alive.format(pids["bob"]))[1].split() == ["alive"]
        disabled_at = time.monotonic()
        update_user(SYSTEM, bob.id, active=False)
        db.session.commit()  # the test is the boundary: its commit sends the refresh job

        def bob_gone() -> bool:
            ok, out = as_team(
                "alice",
                f"{alive.format(pids['bob'])}; getent passwd {account['bob']} || echo no-account",
            )
            return ok and out.split() == ["gone", "no-account"]

        wait_for(bob_gone, 60, "bob's process and account to go")
        print(
            f"bob disabled -> his process killed and account removed: "
            f"{time.monotonic() - disabled_at:.1f} s"
        )
        assert not as_team("bob", "true")[0]
        check = f"{alive.format(pids['alice'])}; cat {WORKSPACE}/notes.txt; ls /home"
        ok, out = as_team("alice", check)
        assert out.split()[:3] == ["alive", "alice", "bob"], out
        assert account["alice"] in out.split() and account["bob"] not in out.split(), out

        # an officer lets the team use sudo with the documented body: pushed at once
        officer = make_user(Role.OFFICER)
        allowed = client.patch(
            f"/api/v1/constellations/{constellation.id}",
            json={"team_sudo": True},
            headers=token_for(officer),
        )
        assert allowed.status_code == 200, allowed.get_json()
        wait_for(lambda: as_team("alice", "sudo -n true")[0], 120, "sudo for the team")


def reaches(executor: SSHExecutor, ocu: SSHTarget, address: str, port: int) -> bool:
    """Return True when the OCU reaches address:port through the VPN (refused counts)."""
    probe = shlex.quote(f"exec 3<>/dev/tcp/{address}/{port}")
    result = executor.run(ocu, f"timeout 3 bash -c {probe}", check=False, timeout=30)
    return bool(result.ok or "refused" in result.stderr)


@contextmanager
def router_of(
    config: Config, constellation: Constellation
) -> Iterator[tuple[SSHExecutor, SSHTarget]]:
    """Connect to the constellation's router as CloudSim does."""
    keys = constellation_keypair(constellation)
    reach = targets(constellation, keys, config)
    with SSHExecutor(machine_host_keys(constellation), secrets=[keys.private]) as executor:
        yield executor, reach["router"]


def _logins_are_in_the_run_s_logs(app: Flask, run: Run, member: User, name: str) -> None:
    """The run's logs hold each field computer's login record; fc1's names the member, by
    account and e-mail, as an officer downloads it with the documented route."""
    db.session.refresh(run)
    stored = {a.filename: a for a in run.artifacts}
    assert {"logins-fc1.tsv", "logins-fc2.tsv"} <= set(stored), sorted(stored)
    officer = make_user(Role.OFFICER)
    body = app.test_client().get(
        f"/api/v1/runs/{run.id}/logs/{stored['logins-fc1.tsv'].id}", headers=token_for(officer)
    )
    assert body.status_code == 200
    lines = [line.split("\t") for line in body.get_data(as_text=True).splitlines()]
    logins = [line for line in lines if line[2] == "login" and line[3] == name]
    assert logins and all(line[4] == member.email for line in logins), lines[-5:]
    assert {line[3] for line in lines if line[2] == "logout"} >= {name}
