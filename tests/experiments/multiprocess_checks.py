"""What the multi-process tests of table2 and pretrain check alike (shared by test_distributed.py and
test_pretrain_seeds.py): a refused command line is one configuration-error line that writes nothing, and an sbatch
example hands srun a protamer command line (run under a stand-in srun that records it)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from mjx_protamer.cli import main

ROOT = Path(__file__).resolve().parents[2]


def assert_refused_in_one_line(argv: list[str], says: str, capsys, here: Path) -> None:
    """`protamer ARGV`, run in the empty folder `here`, exits 2 with one configuration-error line containing
    `says`, and writes nothing."""
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("protamer: configuration error: ") and says in err[0], err
    assert list(here.iterdir()) == []


def srun_argv_of(script_name: str, tmp_path: Path, args: list[str], **env_vars: str) -> list[str]:
    """scripts/SCRIPT_NAME parses (bash -n), asks SLURM for one task a node, and, run in a SLURM job (id 77) with
    `args` and `env_vars`, hands srun `--kill-on-bad-exit=1 .venv/bin/protamer ...`: the protamer arguments."""
    script = ROOT / "scripts" / script_name
    subprocess.run(["bash", "-n", str(script)], check=True)
    assert "#SBATCH --ntasks-per-node=1" in script.read_text()
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "srun").write_text('#!/bin/bash\nprintf "%s\\n" "$@" > "$SRUN_ARGV"\n')
    (bin_dir / "srun").chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k not in ("SEEDS", "OUT", "PROTAMER_DIR")}
    env.update(PATH=f"{bin_dir}:{env['PATH']}", SRUN_ARGV=str(tmp_path / "argv"), SLURM_JOB_ID="77",
               SLURM_SUBMIT_DIR=str(ROOT), **env_vars)
    subprocess.run(["bash", str(script), *args], env=env, check=True, cwd=tmp_path, timeout=60)
    argv = (tmp_path / "argv").read_text().splitlines()
    assert argv[:2] == ["--kill-on-bad-exit=1", ".venv/bin/protamer"]
    return argv[2:]
