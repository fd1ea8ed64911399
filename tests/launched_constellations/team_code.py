"""A team's code stand-in, copied to fc1 by the team: it waits for CloudSim's current-run.json,
then drives the robot with the example controller copied beside it."""

import json
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

from drcsim.client import SimClient
from example_controller import ExampleController

CURRENT_RUN = pathlib.Path("/var/lib/cloudsim/current-run.json")

while not CURRENT_RUN.exists():
    time.sleep(0.5)
run = json.loads(CURRENT_RUN.read_text())
print(f"run {run['run_id']} is on: {run['world']} #{run['config']}", flush=True)
simulator = run["simulator"]
with SimClient(simulator["host"], simulator["command_port"], timeout_s=10.0) as client:
    controller = ExampleController(client, log=lambda line: print(line, flush=True), timeout_s=120)
    if controller.info["world"] != run["world"]:
        sys.exit(f"the simulator runs {controller.info['world']}, not {run['world']}")
    print(json.dumps({"run_id": run["run_id"], "score": controller.run()}), flush=True)
