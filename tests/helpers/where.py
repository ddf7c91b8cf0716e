"""Where the tests' files are: the tests folder, its data, and the repository's root."""

from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
DATA = TESTS / "data"
HELPERS = TESTS / "helpers"
ROOT = TESTS.parent
