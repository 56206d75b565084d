"""The vector-width setting of ``import wallcal`` (src/wallcal/_numba_setup.py): applied before numba
compiles anything, never over the user's own choice, and off with WALLCAL_VECTOR_WIDTH=256."""

import json
import os
import subprocess
import sys

PROBE = (
    "import json, os, wallcal; from llvmlite import binding as ll; "
    "print(json.dumps({'name': os.environ.get('NUMBA_CPU_NAME'), 'features': os.environ.get('NUMBA_CPU_FEATURES'), "
    "'avx512': bool(ll.get_host_cpu_features().get('avx512f', False)), 'host': ll.get_host_cpu_name()}))"
)


def _run(**env):
    base = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_CPU_", "WALLCAL_VECTOR"))}
    out = subprocess.run([sys.executable, "-c", PROBE], env={**base, **env}, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_default_drops_the_256_bit_preference_only_where_it_applies():
    r = _run()
    if r["avx512"] and r["host"] not in {"skylake-avx512", "cascadelake", "cooperlake", "knl", "knm"}:
        assert r["name"] == r["host"]
        assert r["features"].endswith(",-prefer-256-bit")
    else:
        assert r["name"] is None and r["features"] is None


def test_opt_out_and_user_settings_win():
    assert _run(WALLCAL_VECTOR_WIDTH="256")["features"] is None
    r = _run(NUMBA_CPU_NAME="generic")
    assert r["name"] == "generic" and r["features"] is None
