"""The compile-cost benchmark (issue 24, item 7): a row times ``bgc simulate`` cold (fresh
interpreter, empty cache, fresh output directory) and warm, with the model's size; a run
past its timeout is recorded, not waited for; the summary tables the growth from N = 10
to N = 40 and the issue's targets with their verdicts. Times are never asserted beyond
being measured: performance lives in ``make bench``."""

from __future__ import annotations

import csv
import math

import pytest

from bgc.bench import Run, compile_cost
from bgc.bench.chain import write_chain


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow       # 20 s: two cold compiles; make bench runs it in full
def test_a_row_times_a_cold_then_a_warm_first_result_of_a_chain(tmp_path):
    """Chain of 2 links, parasitic: the cold run compiles into an empty cache, the warm
    one finds module and cache and recompiles nothing; the module is the cold run's."""
    model = write_chain(2, tmp_path / "models")
    rows = compile_cost.sweep([("2", model)], ("parasitic",), tmp_path / "work",
                              log=lambda m: None)
    (row,) = rows
    assert row["status"] == "ok", row
    assert row["N"] == "2" and row["method"] == "parasitic"
    assert row["states"] == 24 and row["assignments"] > 24     # 12 per free body
    assert row["ops_rhs"] > 100 and row["ops_jac"] > 100
    assert 0 < row["warm_s"] < row["cold_s"]
    assert row["cold_jit_s"] > row["warm_jit_s"] >= 0       # the cold run compiled
    assert row["warm_recompiled"] is False
    for stage in compile_cost.STAGES:                         # present, NaN if unreported
        assert compile_cost.column(stage) in row
    assert row["stages_reported"] == sum(
        not math.isnan(row[compile_cost.column(s)]) for s in compile_cost.STAGES)
    assert not list((tmp_path / "work").iterdir())           # caches and modules removed


def test_a_run_past_its_timeout_is_killed_and_recorded(tmp_path):
    model = write_chain(3, tmp_path)
    row = compile_cost.measure(model, "lagrange", tmp_path, timeout=0.5)
    assert row["status"] == "timeout after 0.5 s" and row["model"] == "chain_3"
    assert math.isnan(row["cold_s"]) and math.isnan(row["warm_s"])


@pytest.mark.parametrize("report, expected", [
    ({"stages": {"load": 0.1, "machine code": 2.0}}, {"load": 0.1, "machine code": 2.0}),
    ({"timings": {"emit": 1}}, {"emit": 1.0}),
    ({"stats": {"timings": {"integrate": {"seconds": 0.5, "count": 3}}}},
     {"integrate": 0.5}),
    ({"stats": {"compile_time": 3.0}}, {}),
    (None, {}),
])
def test_stages_are_read_from_whichever_key_the_report_has(report, expected):
    assert compile_cost.stages(report) == expected


def _synthetic(n, method, cold, warm=0.5, states=None, **stages):
    return {"N": n, "model": f"chain_{n}", "method": method,
            "states": states or 12 * (int(n) if n != "sarib" else 40), "assignments": 100,
            "ops_rhs": 10, "ops_jac": 10, "cold_s": cold, "warm_s": warm,
            "cold_jit_s": 1.0, "warm_jit_s": 0.1,
            **{compile_cost.column(s): stages.get(s.replace(" ", "_"), math.nan)
               for s in compile_cost.STAGES}, "status": "ok"}


def test_summary_tables_growth_and_targets_from_rows(tmp_path):
    rows = [_synthetic("10", "parasitic", 4.0, load=0.2, machine_code=2.0),
            _synthetic("40", "parasitic", 12.0, load=0.5, machine_code=8.0),
            _synthetic("sarib", "parasitic", 9.0, warm=0.8),
            _synthetic("10", "zcp", 5.0),
            _synthetic("40", "zcp", 30.0, warm=2.0),
            _synthetic("sarib", "zcp", math.nan, warm=math.nan)]
    rows[-1]["status"] = "timeout after 900 s"
    run = Run(tmp_path, quick=False, repeats=1, budget=1.0, log=lambda m: None,
              build=tmp_path / "build")
    compile_cost.report(run, rows)
    text = "\n".join(run.summary)
    # the CSV: one row per model x method, the stage columns kept
    back = _rows(tmp_path / "compile_cost.csv")
    assert [(r["N"], r["method"]) for r in back] == [(r["N"], r["method"]) for r in rows]
    assert {"states", "cold_s", "warm_s", "load_s", "machine_code_s"} <= set(back[0])
    assert (tmp_path / "compile_cost.png").stat().st_size > 10000
    # stages with a number somewhere are tabled; those with none are not
    assert "machine_code_s" in text and "jacobian_s" not in text
    assert "parasitic 3x, zcp 6x" in text
    verdicts = {(t["key"], t["method"]): t["verdict"] for t in compile_cost.targets(rows)}
    assert verdicts == {
        ("sarib_cold_s", "parasitic"): "pass", ("chain40_cold_s", "parasitic"): "pass",
        ("growth_10_40", "parasitic"): "pass", ("warm_s", "parasitic"): "pass",
        ("sarib_cold_s", "zcp"): "FAIL (timeout after 900 s)",
        ("chain40_cold_s", "zcp"): "FAIL", ("growth_10_40", "zcp"): "FAIL",
        ("warm_s", "zcp"): "FAIL (timeout after 900 s)"}
    assert ("| SARIB cold time to first result [s] | zcp | nan | 10 | FAIL (timeout after "
            "900 s) |") in text
    assert "| sarib | zcp | 480 |" in text and "| timeout after 900 s |" in text
    # a target whose runs are missing is not measured, not failed, and not tabled
    assert {t["verdict"] for t in compile_cost.targets(rows[:2])} == {"pass",
                                                                      "not measured"}
    quick = Run(tmp_path / "quick", quick=True, repeats=1, budget=1.0, log=lambda m: None,
                build=tmp_path / "build")
    compile_cost.report(quick, [_synthetic("5", "parasitic", 2.0), _synthetic("10", "parasitic",
                                                                        5.0)])
    text = "\n".join(quick.summary)
    assert "N = 5 to N = 10" in text and "parasitic 2.5x" in text
    assert "need the full run" in text and "| verdict |" not in text and not quick.targets
    # the run's targets (full mode): one line per target over the methods
    assert any(t.startswith("cold time N=40 / N=10 (target <= 4.5): parasitic 3 pass, "
                            "zcp 6 FAIL") for t in run.targets), run.targets
