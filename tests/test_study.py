"""`skdgmpm converge`: table, CSV and plots of a convergence study against an exact solution."""
import csv

import numpy as np
import pytest

from skdgmpm.cli import main
from skdgmpm.errors import InputError
from skdgmpm.study import convergence


def test_converge_command_writes_table_csv_and_plots(tmp_path, capsys):
    out = tmp_path / "study"
    rc = main(["converge", "standing_wave_2d", "--methods", "dgmpm,rk-dgfem", "--orders", "1,2",
               "--cells", "4,8", "--fields", "eps11,P11,v1", "--out", str(out), "--quiet"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "rk-dgfem/rk4" in text and "dgmpm/euler" in text
    rows = list(csv.DictReader(open(out / "convergence.csv")))
    assert len(rows) == 2 + 2 * 2                            # dgmpm has order 1 only
    assert {"method", "order", "cells", "h", "dofs", "wall_s", "L2_P11", "rate_P11"} <= set(rows[0])
    p2 = [r for r in rows if r["method"] == "rk-dgfem/rk4" and r["order"] == "2"]
    assert float(p2[1]["rate_P11"]) > 2.8
    for name in ("error_vs_h.png", "error_vs_time.png"):
        assert (out / name).stat().st_size > 10_000


def test_rates_are_computed_between_successive_grids():
    rows = convergence("standing_wave_2d", ["rk-dgfem/rk2"], [1], [4, 8], fields=["P11"], progress=False)
    expected = np.log2(rows[0]["L2_P11"] / rows[1]["L2_P11"])
    assert np.isnan(rows[0]["rate_P11"]) and np.isclose(rows[1]["rate_P11"], expected)


@pytest.mark.parametrize("args, match", [
    (("bar_elastic_1d", ["ader"], [1], [4]), "not a method"),
    (("partial_impact_2d", ["dgmpm"], [1], [4]), "exact"),
    (("standing_wave_2d", ["dgmpm"], [1], [4], (), ["sigma99"]), "not a field"),
])
def test_bad_study_input(args, match):
    with pytest.raises(InputError, match=match):
        convergence(*args, progress=False)


def test_temporal_study_rates_along_the_time_step_and_unstable_runs_record_error_one():
    # one grid, several CFL numbers: rates are taken against the mean step; WG08's convention
    # records a blown-up run as error 1 and the study goes on
    ok, slow = convergence("standing_wave_2d", ["rk-dgfem/rk2"], [1], [4], fields=["P11"], progress=False,
                           cfls=[0.1, 0.2])
    with pytest.warns(UserWarning, match="von Neumann"):          # CFL 2 is far above the limit 0.69
        stable, blown = convergence("standing_wave_2d", ["dgmpm"], [1], [4], fields=["P11"], progress=False,
                                    cfls=[0.2, 2.0], overrides=["run.t_end=2e-3", "method.cfl_above_limit=true"])
    assert ok["status"] == slow["status"] == stable["status"] == "ok" and blown["status"] == "unstable"
    assert blown["L2_P11"] == 1.0 and np.isnan(blown["rate_P11"])
    assert np.isclose(slow["dt"], 2 * ok["dt"], rtol=0.05)
    expected = np.log(slow["L2_P11"] / ok["L2_P11"]) / np.log(slow["dt"] / ok["dt"])
    assert np.isclose(slow["rate_P11"], expected)


def test_wg08_measure_needs_a_displacement():
    with pytest.raises(InputError, match="wg08"):
        convergence("standing_wave_2d", ["dgmpm"], [1], [4], progress=False, measure="wg08")


def test_compare_draws_the_work_precision_diagram_and_names_the_fastest(tmp_path, capsys):
    out = tmp_path / "cmp"
    rc = main(["compare", "standing_wave_2d", "--methods", "rk-dgfem/rk2,ader-dgfem", "--orders", "1,2",
               "--cells", "4,8", "--fields", "P11", "--out", str(out), "--quiet", "--workers", "2"])
    assert rc == 0
    text = capsys.readouterr().out
    assert "fastest to each accuracy" in text
    rows = list(csv.DictReader(open(out / "compare.csv")))
    assert len(rows) == 2 * 2 * 2 and all(r["status"] == "ok" for r in rows)
    assert (out / "work_precision.png").stat().st_size > 10_000


def test_winners_interpolate_the_time_to_reach_each_accuracy():
    from skdgmpm.study import winners
    rows = [{"method": m, "order": 1, "status": "ok", "wall_s": t, "L2_P11": e}
            for m, t, e in [("a", 1.0, 1e-1), ("a", 10.0, 1e-3), ("b", 5.0, 1e-2), ("b", 8.0, 1e-4)]]
    result = {target: (label, s) for target, label, s in winners(rows, "L2_P11")}
    assert result[1e-1] == ("a P1", 1.0)                        # only a gets there, at once
    assert result[1e-2][0] == "a P1" and np.isclose(result[1e-2][1], np.sqrt(10.0))   # log-log midpoint
    assert result[1e-3][0] == "b P1" and np.isclose(result[1e-3][1], 5.0 * np.sqrt(8.0 / 5.0))
    assert result[1e-4][0] == "b P1" and np.isclose(result[1e-4][1], 8.0) and set(result) == {1e-1, 1e-2, 1e-3, 1e-4}


def test_study_on_a_dask_cluster_over_loopback():
    distributed = pytest.importorskip("distributed")
    from skdgmpm.executor import make_executor
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        pool = make_executor(dask=cluster.scheduler_address)
        try:
            rows = convergence("standing_wave_2d", ["rk-dgfem/rk2"], [1], [4, 8], fields=["P11"],
                               progress=False, executor=pool)
        finally:
            pool.shutdown()
    here = convergence("standing_wave_2d", ["rk-dgfem/rk2"], [1], [4, 8], fields=["P11"], progress=False)
    assert [r["L2_P11"] for r in rows] == [r["L2_P11"] for r in here]      # same runs, same numbers


def test_unreachable_dask_scheduler_is_a_clear_error():
    pytest.importorskip("distributed")
    from skdgmpm.executor import make_executor
    with pytest.raises(InputError, match="--dask tcp://127.0.0.1:9"):
        make_executor(dask="tcp://127.0.0.1:9", timeout="1s")
