import os
from pathlib import Path

import pytest

_SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def cascaded_tanks():
    """The real Cascaded Tanks records; skipped when absent unless CI requires them."""
    from sknlss.datasets import load_cascaded_tanks

    data_home = os.environ.get("SKNLSS_DATA") or (
        str(_SHARED_DATA) if _SHARED_DATA.is_dir() else None
    )
    try:
        return load_cascaded_tanks(data_home=data_home, download=False)
    except FileNotFoundError as exc:
        if os.environ.get("SKNLSS_REQUIRE_DATA") == "1":
            raise
        pytest.skip(f"Cascaded Tanks data not available: {exc}")
