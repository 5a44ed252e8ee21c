"""The disclosed nominal reference logs (independent simulator, truth in the sidecars) come out ``none``."""

from __future__ import annotations

import pytest

from assist.diagnose import diagnose
from conftest import DATA
from ptw_env.logs import read_log
from test_diagnose import assert_found


@pytest.mark.parametrize("name", ["nominal_urban", "nominal_urban_noiseless"])
def test_nominal_reference_log_is_none(name):
    log = read_log(DATA / f"{name}.csv")
    truth = log.meta["truth"]["causes"]
    assert truth == [{"cause": "none", "params": {}}]
    rep = diagnose(log, progress=False)
    assert_found(rep, {})
    j = rep.to_json()
    assert j["verdict"]["causes"] == truth
    # nothing beyond the noise anywhere
    assert all(v["excess"] < 0.3 for v in j["nominal"]["where"]["channels"].values())
