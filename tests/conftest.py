import sys
from pathlib import Path

import pytest

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
