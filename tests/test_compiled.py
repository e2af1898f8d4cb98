"""warm_up compiles the kernels the engine calls, with the types the engine passes them."""

import json
import subprocess
import sys

_SCRIPT = """
import json, sys
from numba.core.dispatcher import Dispatcher
import isf
from isf.compiled import warm_up

def signatures():
    found = {}
    for name, module in list(sys.modules.items()):
        if name == "isf" or name.startswith("isf."):
            for attr, value in vars(module).items():
                if isinstance(value, Dispatcher):  # keyed where defined, not where imported
                    found[value.py_func.__module__ + "." + value.py_func.__name__] = len(value.signatures)
    return found

warm_up()
before = signatures()
cylinder = isf.open_object("shape:cylinder")
isf.plan(isf.load_gripper("paper-parallel"), cylinder, samples=6, seed=0)
isf.plan(isf.load_gripper("three-finger"), cylinder, samples=6, seed=0, repair_collisions=True)
print(json.dumps({"before": before, "after": signatures()}))
"""


def test_warm_up_covers_every_kernel_call_of_a_plan():
    out = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True, check=True)
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    before, after = counts["before"], counts["after"]
    entry_points = {  # the kernels the engine calls from Python (they call the others)
        "isf.lockstep_kernel.run", "isf.lockstep_kernel.enter_level", "isf.lockstep_kernel.score_state",
        "isf.lockstep_kernel.finish_round", "isf.ipfo_kernel.resume", "isf.nearest._query",
        "isf.nearest._query_k", "isf.correspondence._filter_pairs", "isf.chain._frame_kinematics",
        "isf.dense_qp._dual_active_set", "isf.collision_kernel.check_elements",
        "isf.collision_kernel.reverse_clearance", "isf.collision._rigid",
        "isf.repair_step.to_object", "isf.repair_step.motion_rows", "isf.repair_step.step_qp",
        "isf.repair_contacts.contact_pairs",
    }
    assert entry_points <= {name for name, n in before.items() if n}  # compiled by warm_up
    assert after == before  # and a plan compiled nothing more
