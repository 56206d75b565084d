"""The modal kernel calls LAPACK by name (wallcal.engines.lapack), so numba caches it: a fresh process with
an empty kernel cache compiles it, the next fresh process loads it from the cache (no compilation) and
gets the same simulation, bit for bit. The command line's notice of a compilation (wallcal.cli.CompileNotice)
is said in the first process and not in the second."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from wallcal import cli

EXAMPLE = Path(__file__).resolve().parents[1] / "src" / "wallcal" / "examples" / "campaign_a" / "study.toml"

PROBE = """
import hashlib, io, json, sys, wallcal
from numba.core import event
from wallcal import cli
from wallcal.engines import modal

notice = cli.CompileNotice(io.StringIO(), after=0.5)
with event.install_listener(cli.COMPILE_EVENT, notice):
    r = wallcal.simulate(wallcal.load_study(sys.argv[1]))
notice.close()
st = modal.modal_kernel.stats
print(json.dumps({
    "path": r.info["path"],
    "hits": sum(st.cache_hits.values()),
    "misses": sum(st.cache_misses.values()),
    "values": hashlib.sha256(r.simulated.to_numpy().tobytes()).hexdigest(),
    "notice": notice.stream.getvalue(),
}))
"""


@pytest.mark.slow
def test_fresh_process_loads_the_modal_kernel_from_the_cache(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}

    def run():
        out = subprocess.run(
            [sys.executable, "-c", PROBE, str(EXAMPLE)], env=env, capture_output=True, text=True, check=True
        )
        return json.loads(out.stdout.strip().splitlines()[-1])

    cold, warm = run(), run()
    assert cold["path"] == warm["path"] == "modal"
    assert (cold["hits"], cold["misses"]) == (0, 1)
    assert (warm["hits"], warm["misses"]) == (1, 0)
    assert warm["values"] == cold["values"]
    assert cold["notice"] == cli.CompileNotice.MESSAGE + "\n"
    assert warm["notice"] == ""
