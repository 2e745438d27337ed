"""
The stress suite's short mode: every phase against fresh nodes, each must pass.

    .venv/bin/python -m pytest -q test/test_stress.py     # about 90 s on 2 cores

The long mode (``hcloth_stress --seconds 60 --starts 100``) is run by hand for the README.
"""

import os
import subprocess
import sys

import pytest

# nodes in other processes for about a minute
pytestmark = pytest.mark.slow

PHASES = ['1 flood', '2 params', '3 services', '4 churn', '5 signals', '6 sigkill']


def test_short_stress_run_passes_every_phase():
    env = dict(os.environ, AMENT_PREFIX_PATH=os.environ.get('AMENT_PREFIX_PATH') or sys.prefix)
    # the suite bounds its own waits; this timeout is only a backstop for the test run
    done = subprocess.run([sys.executable, '-m', 'hcloth_ros.bench.stress', '--short'],
                          env=env, capture_output=True, text=True, timeout=300)
    out = done.stdout
    verdicts = {}
    for line in out.splitlines():
        for phase in PHASES:
            if line.startswith(phase + ' ') and line.split()[-1] in ('PASS', 'FAIL'):
                verdicts[phase] = line.split()[-1]
    # the whole output on failure: the reasons are printed under each phase
    report = f'{out[-12000:]}\n{done.stderr[-3000:]}'
    assert set(verdicts) == set(PHASES), report
    assert [p for p in PHASES if verdicts[p] != 'PASS'] == [], report
    assert 'every phase passed' in out, report
    assert done.returncode == 0, report
