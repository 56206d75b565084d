"""``import wallcal`` has no process-wide side effects: the environment (numba's CPU settings included)
is left exactly as it was, and numba's configuration is not changed for the user's other code."""

import json
import os
import subprocess
import sys

PROBE = (
    "import json, os; before = dict(os.environ); from numba.core import config; "
    "cfg = (config.CPU_NAME, config.CPU_FEATURES); import wallcal, wallcal.engines.fd; "
    "after = dict(os.environ); "
    "print(json.dumps({'changed': sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k)), "
    "'config_same': cfg == (config.CPU_NAME, config.CPU_FEATURES)}))"
)


def test_import_leaves_the_environment_and_numba_config_unchanged():
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_CPU_")}
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["changed"] == []
    assert r["config_same"]
