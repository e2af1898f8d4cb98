"""warm_up compiles the kernels the engine calls, with the types the engine passes them."""

import json
import subprocess
import sys

_SCRIPT = """
import json, sys
from numba.core.dispatcher import Dispatcher
import isf
from isf.warming import warm_up

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
    out = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True,
                         check=True)
    counts = json.loads(out.stdout.strip().splitlines()[-1])
    before, after = counts["before"], counts["after"]
    entry_points = {  # the kernels the engine calls from Python (they call the others)
        "isf.fitting.engine_kernel.run",
        "isf.fitting.engine_kernel.enter_level", "isf.fitting.engine_kernel.score_state",
        "isf.fitting.engine_kernel.finish_round", "isf.fitting._ipfo_kernel.alternate",
        "isf.search.nearest.nearest_with_guesses", "isf.search.nearest._query_k",
        "isf.fitting.correspondence.filter_pairs", "isf.gripper.chain.compiled_frame_kinematics",
        "isf.collision.kernel.check_elements",
        "isf.collision.kernel.reverse_clearance", "isf.collision.checker._rigid",
        "isf.repair._step.to_object", "isf.repair._step.motion_rows", "isf.repair._step.step_qp",
        "isf.repair._contacts.contact_pairs",
    }
    assert entry_points <= {name for name, n in before.items() if n}  # compiled by warm_up
    assert after == before  # and a plan compiled nothing more
