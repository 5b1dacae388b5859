"""``thermotouch model``: the calculator's output and its errors."""

import json

import numpy as np
import pytest

from edge.physics.forward import simulate
from edge.physics.solids import Solid
from tests.support.cli import run


def test_json_glass_matches_model(capsys):
    code, out, err = run(capsys, "model", "--k", "1.097", "--rho", "2458.4", "--c", "809", "--json")
    assert code == 0 and err == ""
    d = json.loads(out)
    ref = simulate(Solid(1.097, 2458.4, 809), 7.7e7, 1.95)
    np.testing.assert_allclose(d["t_s"], ref.t_s)
    np.testing.assert_allclose(d["T_f_K"], ref.T_f_K, rtol=1e-12)
    np.testing.assert_allclose(d["q_f_W_m2"], ref.q_f_W_m2, rtol=1e-12)
    assert d["k_W_mK"] == 1.097 and d["back"] == "fixed" and d["scheme"] == "default"


def test_material_and_options(capsys):
    code, out, _ = run(capsys, "model", "--material", "pmma", "--back", "infinite", "--duration", "1", "--json")
    d = json.loads(out)
    assert code == 0 and d["material"] == "pmma" and d["thickness_m"] is None
    assert len(d["t_s"]) == 101 and d["T_f_K"][-1] > 0.5


def test_table_output(capsys):
    code, out, _ = run(capsys, "model", "--material", "tempered_glass", "--scheme", "paper")
    assert code == 0
    assert "T_f (K)" in out and "scheme paper" in out
    assert len(out.strip().splitlines()) >= 12


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["model", "--k", "1", "--rho", "2"], "--c"),
        (["model", "--k", "-1", "--rho", "2", "--c", "3"], "--k"),  # checked on the host: names the option
        (["model", "--material", "unobtainium"], "unobtainium"),
        (["model", "--k", "x", "--rho", "1", "--c", "1"], "--k"),
        (["model", "--k", "1", "--rho", "1", "--c", "1", "--duration", "0"], "--duration"),
        (["model", "--k", "1", "--rho", "1", "--c", "1", "--back", "wobbly"], "--back"),
        (["model"], "required"),
    ],
)
def test_bad_arguments_one_line_exit_2(capsys, argv, needle):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ""
    assert len(err.strip().splitlines()) == 1 and needle in err


# The console entry (``python -m host.cli model ... --json`` in a fresh process) is run by
# tests/host/test_blas.py::test_the_console_entry_runs_and_limits_blas_threads, which checks its JSON and the
# BLAS limit it sets in one process.
