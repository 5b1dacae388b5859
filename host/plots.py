"""Plots of one touch: measured and model-fitted heat flux and temperature (like the paper's Figs. 10, 12, 14).

The model curve is recomputed on the host from the record's resampled series
with the same bundle the device used (:class:`edge.estimation.estimate.Estimator`
returns the fitted temperature ``fit_T_K`` on its model grid ``t_model_s``);
the flux panel shows the measured samples and the resampled flux the model
was driven with.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Mapping

import numpy as np

__all__ = ["result_title", "plot_touch", "TouchFigure", "PlotProcess", "PlotError"]

#: The series entries a plot reads (the rest of a record is not sent to a plot process).
_SERIES_KEYS = ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_q_W_m2", "T0_C", "q_offset_W_m2")


class PlotError(OSError):
    """A plot could not be written (the message names the file)."""


def _pm(v: float | None, u: float | None, scale: float = 1.0) -> str:
    """``v ± u`` rounded to two significant digits of ``u``."""
    if v is None:
        return "n/a"
    v, u = v * scale, (u or 0.0) * scale
    if not u > 0:
        return f"{v:.4g}"
    decimals = 1 - int(math.floor(math.log10(u)))
    if decimals >= 0:
        return f"{v:.{decimals}f} ± {u:.{decimals}f}"
    q = 10.0 ** (-decimals)
    return f"{round(v / q) * q:.0f} ± {round(u / q) * q:.0f}"


def result_title(result: Mapping[str, Any], label: str = "") -> str:
    """Two title lines: e, k and alpha with uncertainties; method, material and flags."""
    r = result
    if r.get("effusivity_W_s05_m2K") is None:
        line1 = "no estimate: " + (", ".join(r.get("flags") or []) or "no result")
    else:
        line1 = (f"e = {_pm(r['effusivity_W_s05_m2K'], r['effusivity_W_s05_m2K_u'])} W s$^{{0.5}}$/(m$^2$ K),  "
                 f"k = {_pm(r['k_W_mK'], r['k_W_mK_u'])} W/(m K),  "
                 f"α = {_pm(r['alpha_m2_s'], r['alpha_m2_s_u'], 1e6)} mm$^2$/s")
    mat = f"{r['material']} ({r['material_confidence'] * 100:.0f} %)" if r.get("material") else "no material"
    flags = ", ".join(r.get("flags") or []) or "no flags"
    line2 = f"{label + ': ' if label else ''}{r['method']} method, {mat}, {flags}"
    return f"{line2}\n{line1}"


class TouchFigure:
    """A two-panel figure of one touch, drawn once and re-used for touch after touch.

    Building a Matplotlib figure (axes, ticks, labels, mathtext) costs more
    than drawing it, and a constrained layout re-measures every text on each
    save (half the demo's time in 2026-11); so the layout is fixed by hand and
    each new touch only replaces the lines' data and the titles.

    Use :meth:`draw` for each touch and :meth:`close` (or ``with``) at the end.
    """

    def __init__(self) -> None:
        import matplotlib  # noqa: PLC0415

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415

        self._plt = plt
        fig, (ax_q, ax_T) = plt.subplots(1, 2, figsize=(11, 4.4))
        # Fixed margins: room for the two-line title and the axis labels at this size.
        fig.subplots_adjust(left=0.07, right=0.985, bottom=0.12, top=0.82, wspace=0.22)
        self.fig, self.ax_q, self.ax_T = fig, ax_q, ax_T
        self._q_meas, = ax_q.plot([], [], "o", ms=4, color="tab:blue", label="measured")
        self._q_grid, = ax_q.plot([], [], "-", color="tab:orange", lw=1.5, label="resampled (model input)")
        ax_q.set_xlabel("time since heater on (s)")
        ax_q.set_ylabel("heat flux $q_f$ (W/m$^2$)")
        # y given: no top ticks here, so the title sits where Matplotlib would put it, and it skips
        # measuring every axis's tick labels to place it at each save.
        ax_q.set_title("(a) heat flux into the object", y=1.0)
        ax_q.grid(alpha=0.3)
        self._T_meas, = ax_T.plot([], [], "o", ms=4, color="tab:blue", label="measured")
        self._T_fit, = ax_T.plot([], [], "-", color="tab:red", lw=1.5, label="model fit")
        ax_T.set_xlabel("time since heater on (s)")
        ax_T.set_ylabel("excess temperature $T_f - T_0$ (K)")
        ax_T.set_title("(b) excess temperature", y=1.0)
        ax_T.grid(alpha=0.3)
        self._title = fig.suptitle("", fontsize=10)

    def draw(self, path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
             label: str = "") -> Path:
        """Write one touch to ``path`` (see :func:`plot_touch` for the arguments)."""
        t = np.asarray(series["raw_t_s"], float)
        heat = t >= 0
        T0 = float(series.get("T0_C") or 0.0)
        q0 = float(series.get("q_offset_W_m2") or 0.0)
        self._q_meas.set_data(t[heat], np.asarray(series["raw_q_W_m2"], float)[heat] - q0)
        has_grid = series.get("grid_t_s") is not None
        self._q_grid.set_data(*((series["grid_t_s"], series["grid_q_W_m2"]) if has_grid else ([], [])))
        self._T_meas.set_data(t[heat], np.asarray(series["raw_T_C"], float)[heat] - T0)
        has_fit = fit is not None and fit.fit_T_K is not None
        self._T_fit.set_data(*((fit.t_model_s, fit.fit_T_K) if has_fit else ([], [])))
        if has_fit:
            self._T_fit.set_label(f"model fit ({fit.method})")
        # Legends name only the curves this touch has.
        self.ax_q.legend(handles=[self._q_meas] + ([self._q_grid] if has_grid else []), loc="lower right")
        self.ax_T.legend(handles=[self._T_meas] + ([self._T_fit] if has_fit else []),
                         loc="upper left")  # the rise fills the lower right
        for ax in (self.ax_q, self.ax_T):
            ax.relim()
            ax.autoscale_view()
        self._title.set_text(result_title(result, label))
        out = Path(path)
        from host.atomic import atomic_path  # noqa: PLC0415

        # The directory must exist (nothing is created behind the caller's back); written atomically.
        fmt = out.suffix.lstrip(".").lower() or "png"
        with atomic_path(out) as tmp:
            # zlib's fastest level: a plot's flat colours compress almost as well as at the
            # default level, in less time.
            png = {"pil_kwargs": {"compress_level": 1}} if fmt == "png" else {}
            self.fig.savefig(tmp, dpi=110, format=fmt, **png)
        return out

    def close(self) -> None:
        """Release the figure."""
        self._plt.close(self.fig)

    def __enter__(self) -> "TouchFigure":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def plot_touch(path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
               label: str = "", *, figure: TouchFigure | None = None) -> Path:
    """Write a two-panel PNG of one touch.

    Parameters
    ----------
    path : str or Path
        Output file in an existing directory; its suffix picks the format
        (``.png``, ``.pdf``, ``.svg``; none: PNG). Written atomically.
    series : mapping
        The stored record with ``raw_t_s``, ``raw_T_C``, ``raw_q_W_m2``,
        ``grid_t_s``, ``grid_q_W_m2``, ``T0_C`` and ``q_offset_W_m2``.
    result : mapping
        The device's result dict (title).
    fit : edge.estimation.result.Estimate
        Host re-estimate on the same record (``t_model_s``, ``fit_T_K``).
    label : str
        Scene or sample name for the title.
    figure : TouchFigure, optional
        A figure to draw into and keep (many touches); default: a new one, closed after.
    """
    if figure is not None:
        return figure.draw(path, series, result, fit, label)
    with TouchFigure() as fig:
        return fig.draw(path, series, result, fit, label)


def _jsonable(x: Any) -> Any:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"cannot send {type(x).__name__} to the plot process")


class PlotProcess:
    """Draw touches in a child process while the caller goes on measuring.

    A plot is mostly Python text layout, so in the caller's process it takes
    the interpreter away from the simulated probe; in a child it runs on the
    other core. Jobs go over the child's stdin as JSON lines (plain numbers
    and strings: nothing is pickled) and the child answers one JSON line per
    plot. :meth:`close` waits for every plot and raises :class:`PlotError`
    naming the first file that could not be written.

    Use as a context manager; :meth:`submit` per touch.
    """

    def __init__(self) -> None:
        self._paths: list[Path] = []
        self._closed = False
        self._proc = subprocess.Popen([sys.executable, "-m", "host.plots"], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def submit(self, path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
               label: str = "") -> Path:
        """Queue one plot (arguments as :func:`plot_touch`); returns its path (written by :meth:`close`)."""
        out = Path(path)
        job = {"path": str(out), "label": label, "result": dict(result),
               "series": {k: series.get(k) for k in _SERIES_KEYS},
               "fit": None if fit is None or fit.fit_T_K is None else
               {"t_model_s": fit.t_model_s, "fit_T_K": fit.fit_T_K, "method": fit.method}}
        try:
            self._proc.stdin.write(json.dumps(job, default=_jsonable) + "\n")
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise PlotError(f"plot process ended before {out} was drawn: {self._why(exc)}") from None
        self._paths.append(out)
        return out

    def _why(self, exc: BaseException | None = None) -> str:
        try:
            err = self._proc.communicate(timeout=5)[1] if self._proc.poll() is None else self._proc.stderr.read()
        except (subprocess.TimeoutExpired, OSError, ValueError):
            err = ""
        lines = [ln for ln in (err or "").splitlines() if ln.strip()]
        return lines[-1] if lines else (str(exc) if exc else f"exit status {self._proc.returncode}")

    def close(self) -> list[Path]:
        """Wait for every queued plot; the paths written, in order.

        Raises
        ------
        PlotError
            A plot failed, or the process ended early (the message says which file and why).
        """
        if self._closed:
            return list(self._paths)
        self._closed = True
        try:
            out, err = self._proc.communicate(timeout=60 + 10 * len(self._paths))
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.communicate()
            raise PlotError(f"plot process did not finish {len(self._paths)} plots in time") from None
        done = {}
        for line in out.splitlines():
            reply = json.loads(line)
            if reply.get("error"):
                raise PlotError(reply["error"])
            done[reply["path"]] = True
        missing = [p for p in self._paths if str(p) not in done]
        if missing or self._proc.returncode != 0:
            lines = [ln for ln in err.splitlines() if ln.strip()]
            why = lines[-1] if lines else f"exit status {self._proc.returncode}"
            raise PlotError(f"plot process ended before {missing[0] if missing else 'its end'}: {why}")
        return list(self._paths)

    def __enter__(self) -> "PlotProcess":
        return self

    def __exit__(self, exc_type: Any, *exc: object) -> None:
        if exc_type is None:
            self.close()
        elif not self._closed:  # the caller failed: do not wait for plots nobody will look at
            self._closed = True
            self._proc.kill()
            self._proc.communicate()


def _serve(stdin: Any, stdout: Any) -> int:
    """The plot process: one JSON job per line in, one JSON reply per line out."""
    with TouchFigure() as figure:
        for line in stdin:
            job = json.loads(line)
            fit = None if job["fit"] is None else SimpleNamespace(**job["fit"])
            try:
                figure.draw(job["path"], job["series"], job["result"], fit, job["label"])
                reply = {"path": job["path"]}
            except OSError as exc:
                reply = {"path": job["path"], "error": f"cannot write plot {job['path']}: {exc.strerror or exc}"}
            stdout.write(json.dumps(reply) + "\n")
            stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(_serve(sys.stdin, sys.stdout))
