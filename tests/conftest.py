import sys
from pathlib import Path

import pytest
from hypothesis import settings

# `make test` draws the same examples on every run, so a check passes or fails for the code and not
# for the draw; `make fuzz` explores afresh (NCADAPT_HYPOTHESIS=explore).
settings.register_profile("test", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(__import__("os").environ.get("NCADAPT_HYPOTHESIS", "test"))

sys.path.insert(0, str(Path(__file__).parent))

from rs274 import RS274  # noqa: E402

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

needs_rs274 = pytest.mark.skipif(
    RS274 is None and not __import__("os").environ.get("CI"),
    reason="LinuxCNC's rs274 is not installed (make test installs it)",
)


@pytest.fixture
def examples() -> Path:
    return EXAMPLES
