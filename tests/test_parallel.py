"""Searches scale out through joblib: the same search on a dask cluster."""

import numpy as np
import pytest
from joblib import parallel_config
from sklearn.model_selection import GridSearchCV, TimeSeriesSplit

from sknlss import BLAEstimator
from sknlss.metrics import make_transient_scorer


def _records():
    rng = np.random.default_rng(3)
    u = 0.3 * rng.standard_normal((600, 1))
    x = np.zeros(2)
    y = np.empty(600)
    for t, ut in enumerate(u[:, 0]):
        y[t] = x[0] + 0.1 * x[0] ** 2
        x = np.array([1.2 * x[0] - 0.5 * x[1] + ut, x[0]])
    return u, y + 1e-3 * rng.standard_normal(600)


def _search(n_jobs):
    return GridSearchCV(
        BLAEstimator(),
        {"n_states": [1, 2, 3], "lpm_order": [1, 2]},
        cv=TimeSeriesSplit(n_splits=3),
        scoring=make_transient_scorer("rms", n_transient=20),
        n_jobs=n_jobs,
    )


def test_grid_search_on_a_dask_cluster_matches_the_sequential_run():
    distributed = pytest.importorskip("dask.distributed")
    u, y = _records()
    sequential = _search(n_jobs=None).fit(u, y)
    with distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        host="127.0.0.1",
        dashboard_address=None,
    ) as cluster, distributed.Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        with parallel_config(backend="dask"):
            parallel = _search(n_jobs=-1).fit(u, y)
    assert parallel.best_params_ == sequential.best_params_
    np.testing.assert_allclose(
        parallel.cv_results_["mean_test_score"],
        sequential.cv_results_["mean_test_score"],
        rtol=1e-10,
    )
