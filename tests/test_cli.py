import subprocess
import sys


def test_help_lists_subcommands():
    out = subprocess.run([sys.executable, "-m", "gsbench.cli", "--help"], capture_output=True, text=True, check=True).stdout
    for cmd in ["make-scene", "train", "eval", "ablate", "report", "stress"]:
        assert cmd in out
