import os
from pathlib import Path

import pytest

_SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def _load_or_skip(loader, title):
    """Real benchmark records; skipped when absent unless CI requires them."""
    data_home = os.environ.get("SKNLSS_DATA") or (
        str(_SHARED_DATA) if _SHARED_DATA.is_dir() else None
    )
    try:
        return loader(data_home=data_home, download_if_missing=False)
    except FileNotFoundError as exc:
        if os.environ.get("SKNLSS_REQUIRE_DATA") == "1":
            raise
        pytest.skip(f"{title} data not available: {exc}")


@pytest.fixture(scope="session")
def cascaded_tanks():
    """The real Cascaded Tanks records."""
    from sknlss.datasets import fetch_cascaded_tanks

    return _load_or_skip(fetch_cascaded_tanks, "Cascaded Tanks")


@pytest.fixture(scope="session")
def silverbox():
    """The real Silverbox records."""
    from sknlss.datasets import fetch_silverbox

    return _load_or_skip(fetch_silverbox, "Silverbox")
