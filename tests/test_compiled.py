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
from isf.warming import _cached, _kernels
uncached = sorted(k.py_func.__module__ + "." + k.py_func.__name__ for k in _kernels() if not _cached(k))
cylinder = isf.open_object("shape:cylinder")
isf.plan(isf.load_gripper("paper-parallel"), cylinder, samples=6, seed=0)
isf.plan(isf.load_gripper("three-finger"), cylinder, samples=6, seed=0, repair_collisions=True)
print(json.dumps({"before": before, "after": signatures(), "uncached": uncached}))
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
    # every kernel that warm_up counts in its progress (those not cached yet) is in the cache
    # after it: a first run's count reaches its total
    assert counts["uncached"] == []


def test_two_processes_warming_up_at_once_both_succeed():
    # one compiles (or loads) while the other waits on the cache's lock, then loads
    code = "from isf.warming import warm_up; warm_up(); print('warm')"
    runs = [subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for run in runs:
        out, err = run.communicate(timeout=1800)
        assert run.returncode == 0, err
        assert out.strip() == "warm" and "Traceback" not in err
