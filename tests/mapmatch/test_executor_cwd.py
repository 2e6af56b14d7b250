"""Workers run this process's code, whatever package of that name the working directory holds."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import mapmatch

ROOT = Path(mapmatch.__file__).resolve().parents[1]

PROBE = """
import sys


def where(task):
    return sys.modules["mapmatch"].__file__
"""

RUN = """
import probe
from mapmatch.batch.executors import make_executor

if __name__ == "__main__":
    pool = make_executor(2, None, preload=["mapmatch.batch.executors"])
    for _, outcome in pool.run(probe.where, [0]):
        print(outcome)
    pool.close()
"""


def test_workers_import_this_process_package_not_the_working_directorys(tmp_path: Path) -> None:
    # a snapshot run from inside another checkout: its own mapmatch first on its path, and a
    # different one in the working directory, which a fork server would import first
    checkout = tmp_path / "checkout"
    (checkout / "mapmatch").mkdir(parents=True)
    (checkout / "mapmatch" / "__init__.py").write_text("DECOY = True\n")
    scripts = tmp_path / "scripts"
    scripts.mkdir()
    (scripts / "probe.py").write_text(PROBE)
    (scripts / "run.py").write_text(RUN)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(scripts), str(ROOT)])}
    done = subprocess.run(
        [sys.executable, str(scripts / "run.py")],
        cwd=checkout,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(ROOT / "mapmatch" / "__init__.py"), done.stdout + done.stderr
