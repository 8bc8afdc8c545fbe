"""Where the repository's files are, wherever a test module sits under tests/."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repository: README.md, examples/, benchmarks/, fdbench/
