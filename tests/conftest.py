import json
import os
from pathlib import Path

import numpy as np
import pytest

_SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(autouse=True)
def _seeded_global_random_state():
    """Estimators left at random_state=None draw their random starts from
    NumPy's global generator: seeded, every test repeats from run to run."""
    np.random.seed(0)


def _data_home():
    return os.environ.get("SKNLSS_DATA") or (
        str(_SHARED_DATA) if _SHARED_DATA.is_dir() else None
    )


def _load_or_skip(loader, title):
    """Shared data read by ``loader(data_home)``; skipped when absent unless CI
    requires them."""
    try:
        return loader(_data_home())
    except FileNotFoundError as exc:
        if os.environ.get("SKNLSS_REQUIRE_DATA") == "1":
            raise
        pytest.skip(f"{title} data not available: {exc}")


def _read_reference_model(data_home):
    path = Path(data_home or "") / "pnlss_tutorial" / "true_model.json"
    if data_home is None or not path.is_file():
        raise FileNotFoundError(path)
    return json.loads(path.read_text())


@pytest.fixture(scope="session")
def cascaded_tanks():
    """The real Cascaded Tanks records."""
    from sknlss.datasets import fetch_cascaded_tanks

    return _load_or_skip(
        lambda home: fetch_cascaded_tanks(data_home=home, download_if_missing=False),
        "Cascaded Tanks")


@pytest.fixture(scope="session")
def silverbox():
    """The real Silverbox records."""
    from sknlss.datasets import fetch_silverbox

    return _load_or_skip(
        lambda home: fetch_silverbox(data_home=home, download_if_missing=False), "Silverbox")


@pytest.fixture(scope="session")
def pnlss_tutorial_model():
    """The reference PNLSS system as the shared data describe it."""
    return _load_or_skip(_read_reference_model, "PNLSS tutorial")
