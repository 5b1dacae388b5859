"""Plots of one touch: measured and model-fitted heat flux and temperature (like the paper's Figs. 10, 12, 14).

One code path for every touch plot: ``measure --plot`` draws with :class:`TouchFigure` in
process (Matplotlib imported by :func:`preload` while the touch runs), the demo through
:class:`PlotProcess` (a child process drawing with the same class); what a figure shows is computed by
:func:`host.plot_data.touch_plot_data` (data with the answer's model curve and its
band at e -+ u(e), residuals, the pre-contact phase and the fit's window, the
touch's identification), and the reports take their Matplotlib from :func:`pyplot`.

The method's curve is recomputed on the host from the record's resampled series
with the same bundle the device used (:class:`edge.estimation.estimate.Estimator`
returns the fitted temperature ``fit_T_K`` on its model grid ``t_model_s``); a
calibrated sensor chain's answer is drawn with the chain's own curve (it needs
the device's calibration, ``CALIBRATION_GET``).
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

__all__ = ["result_title", "plot_touch", "TouchFigure", "PlotProcess", "PlotError", "pyplot", "mpl_config_dir",
           "preload"]

#: The series entries a plot reads (the rest of a record is not sent to a plot process).
_SERIES_KEYS = ("raw_t_s", "raw_T_C", "raw_q_W_m2", "grid_t_s", "grid_dT_K", "grid_q_W_m2", "T0_C",
                "q_offset_W_m2")


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
    """A touch's figure, drawn once and re-used for touch after touch (what it shows: :mod:`host.plot_data`).

    Panels: (a) the heat flux into the object, measured and resampled; (b) the excess temperature --
    every measured sample, the grid the method fitted, the answer's model curve with its band at
    e -+ u(e) (k = 1); (c) the residuals of that fit with the band's half-width. The pre-contact phase
    and the window the fit used are shaded in every panel; the title identifies the touch
    (measurement id, UTC time, power, model and calibration) and states the answer.

    Building a Matplotlib figure (axes, ticks, labels, mathtext) costs more than drawing it, and a
    constrained layout re-measures every text on each save; so the layout is fixed by hand and each
    new touch only replaces the artists' data and the titles. Matplotlib runs on Agg, imported once
    per process (its font cache is built once per machine, not per call).

    Use :meth:`draw` for each touch and :meth:`close` (or ``with``) at the end.
    """

    def __init__(self) -> None:
        plt = pyplot()
        self._plt = plt
        fig = plt.figure(figsize=(11, 6.4))
        gs = fig.add_gridspec(2, 2, height_ratios=(3, 1.25), left=0.07, right=0.985, bottom=0.085, top=0.83,
                              wspace=0.22, hspace=0.08)
        ax_q = fig.add_subplot(gs[:, 0])
        ax_T = fig.add_subplot(gs[0, 1])
        ax_r = fig.add_subplot(gs[1, 1], sharex=ax_T)
        self.fig, self.ax_q, self.ax_T, self.ax_r = fig, ax_q, ax_T, ax_r
        self._q_meas, = ax_q.plot([], [], "o", ms=3, color="tab:blue", label="measured")
        self._q_grid, = ax_q.plot([], [], "-", color="tab:orange", lw=1.5, label="resampled (model input)")
        ax_q.set_xlabel("time since heater on (s)")
        ax_q.set_ylabel("heat flux $q_f$ (W/m$^2$)")
        # y given: the title sits where Matplotlib would put it without measuring the tick labels.
        ax_q.set_title("(a) heat flux into the object", y=1.0)
        ax_q.grid(alpha=0.3)
        self._T_meas, = ax_T.plot([], [], "o", ms=3, color="0.55", label="measured")
        self._T_grid, = ax_T.plot([], [], "s", ms=3.5, mfc="none", color="tab:blue", label="fitted data")
        self._T_fit, = ax_T.plot([], [], "-", color="tab:red", lw=1.6, label="model fit")
        self._band = None
        ax_T.set_ylabel("excess temperature $T - T_0$ (K)")
        ax_T.set_title("(b) excess temperature, model at e ± u(e) (k = 1)", y=1.0)
        ax_T.grid(alpha=0.3)
        ax_T.tick_params(labelbottom=False)
        self._r_pts, = ax_r.plot([], [], "o", ms=3, color="tab:blue", label="data − model")
        self._r_band = None
        ax_r.axhline(0.0, color="tab:red", lw=1.0)
        ax_r.set_xlabel("time since heater on (s)")
        ax_r.set_ylabel("residual (K)")
        ax_r.grid(alpha=0.3)
        self._spans: list = []
        self._legend_keys: dict[int, tuple] = {}
        self._note = ax_T.text(0.98, 0.04, "", transform=ax_T.transAxes, ha="right", va="bottom", fontsize=8,
                               color="0.3")
        self._title = fig.suptitle("", fontsize=10)

    def _legend(self, ax: Any, handles: list, loc: str) -> None:
        """A legend of ``handles``, built again only when its entries change (a legend's layout is a large
        part of a draw, and touch after touch of the demo has the same entries)."""
        key = tuple(h.get_label() for h in handles)
        if self._legend_keys.get(id(ax)) == key and ax.get_legend() is not None:
            return
        ax.legend(handles=handles, loc=loc, fontsize=8)
        self._legend_keys[id(ax)] = key

    def _shade(self, data: dict) -> None:
        for span in self._spans:
            span.remove()
        self._spans = []
        t0, t1 = data["pre_contact"]
        for ax in (self.ax_q, self.ax_T, self.ax_r):
            if t1 > t0:
                self._spans.append(ax.axvspan(t0, t1, color="0.85", alpha=0.6, lw=0,
                                              label=data["pre_contact_label"] if ax is self.ax_q else None))
            if data["window"] is not None:
                w0, w1, lab = data["window"]
                self._spans.append(ax.axvspan(w0, w1, color="tab:green", alpha=0.07, lw=0,
                                              label=lab if ax is self.ax_q else None))

    def draw(self, path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
             label: str = "", *, calibration: Any = None) -> Path:
        """Write one touch to ``path`` (see :func:`plot_touch` for the arguments)."""
        from host.plot_data import touch_plot_data  # noqa: PLC0415

        data = touch_plot_data(series, result, fit, calibration)
        self.data = data
        raw, grid, curve, res = data["raw"], data["grid"], data["curve"], data["residual"]
        self._q_meas.set_data(raw["t_s"], raw["q_W_m2"])
        has_grid_q = grid is not None and grid["q_W_m2"] is not None
        self._q_grid.set_data(*((grid["t_s"], grid["q_W_m2"]) if has_grid_q else ([], [])))
        self._T_meas.set_data(raw["t_s"], raw["dT_K"])
        show_grid = grid is not None and grid["dT_K"] is not None and curve is not None and curve["kind"] == "method"
        self._T_grid.set_data(*((grid["t_s"], grid["dT_K"]) if show_grid else ([], [])))
        for band in (self._band, self._r_band):
            if band is not None:
                band.remove()
        self._band = self._r_band = None
        if curve is not None:
            self._T_fit.set_data(curve["t_s"], curve["dT_K"])
            self._T_fit.set_label(curve["label"])
            self._band = self.ax_T.fill_between(curve["t_s"], curve["lo"], curve["hi"], color="tab:red", alpha=0.18,
                                                lw=0, label="model at e ± u(e)")
        else:
            self._T_fit.set_data([], [])
        if res is not None:
            self._r_pts.set_data(res["t_s"], res["r_K"])
            self._r_band = self.ax_r.fill_between(res["t_s"], -res["half_band_K"], res["half_band_K"],
                                                  color="tab:red", alpha=0.18, lw=0)
        else:
            self._r_pts.set_data([], [])
        self._note.set_text(data["note"] or "")
        self._shade(data)
        handles_T = [self._T_meas] + ([self._T_grid] if show_grid else [])
        handles_T += [self._T_fit, self._band] if curve is not None else []
        shaded = [sp for sp in self._spans if sp.axes is self.ax_q]
        self._legend(self.ax_T, handles_T, "upper left")
        self._legend(self.ax_q, [self._q_meas] + ([self._q_grid] if has_grid_q else []) + shaded, "lower right")
        for ax in (self.ax_q, self.ax_T, self.ax_r):
            ax.relim()
            ax.autoscale_view()
        self._title.set_text(data["identification"] + "\n" + result_title(result, label))
        out = Path(path)
        from host.atomic import atomic_path  # noqa: PLC0415

        # The directory must exist (nothing is created behind the caller's back); written atomically.
        fmt = out.suffix.lstrip(".").lower() or "png"
        with atomic_path(out) as tmp:
            # zlib's fastest level: a plot's flat colours compress almost as well as at the
            # default level, in less time.
            png = {"pil_kwargs": {"compress_level": 1}} if fmt == "png" else {}
            self.fig.savefig(tmp, dpi=100, format=fmt, **png)
        return out

    def close(self) -> None:
        """Release the figure."""
        self._plt.close(self.fig)

    def __enter__(self) -> "TouchFigure":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def mpl_config_dir(env: Mapping[str, str] | None = None) -> str | None:
    """A persistent directory for Matplotlib's font cache when its own is not writable (None: its own is).

    Matplotlib keeps its font list in ``$MPLCONFIGDIR`` or ``~/.config/matplotlib`` / ``~/.cache``; where
    neither can be written (a service account, a read-only home) it builds the list again in a new
    temporary directory on every import -- seconds per plot. Then ``$XDG_CACHE_HOME/thermotouch/matplotlib``
    (or the temporary directory's ``thermotouch-matplotlib-<uid>``) is used, so it is built once.
    """
    import os  # noqa: PLC0415
    import tempfile  # noqa: PLC0415

    env = os.environ if env is None else env
    if env.get("MPLCONFIGDIR"):
        return None
    home = Path(env.get("HOME") or "~").expanduser()
    for own in (Path(env.get("XDG_CONFIG_HOME") or home / ".config") / "matplotlib",
                Path(env.get("XDG_CACHE_HOME") or home / ".cache") / "matplotlib"):
        probe = own
        while not probe.exists() and probe != probe.parent:
            probe = probe.parent          # Matplotlib creates the missing directories, if it can
        if probe.is_dir() and os.access(probe, os.W_OK | os.X_OK):
            return None
    base = env.get("XDG_CACHE_HOME")
    target = (Path(base) / "thermotouch" / "matplotlib" if base else
              Path(tempfile.gettempdir()) / f"thermotouch-matplotlib-{os.getuid()}")
    try:
        target.mkdir(parents=True, exist_ok=True, mode=0o700)
    except OSError:
        return None
    return str(target) if os.access(target, os.W_OK | os.X_OK) else None


def pyplot():
    """Matplotlib's pyplot on Agg (no display), for every plot of the package (this module's and the reports').

    Its font cache goes to :func:`mpl_config_dir` where Matplotlib's own directory cannot be written.
    """
    import os  # noqa: PLC0415
    import sys as _sys  # noqa: PLC0415

    if "matplotlib" not in _sys.modules:
        where = mpl_config_dir()
        if where is not None:
            os.environ["MPLCONFIGDIR"] = where
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    return plt


def preload() -> None:
    """Import Matplotlib (:func:`pyplot`) in a background thread: a caller that will plot after waiting on
    a device (``measure --plot``) has it ready; a later import waits for this one, never repeats it."""
    import threading  # noqa: PLC0415

    threading.Thread(target=pyplot, name="matplotlib-preload", daemon=True).start()


def plot_touch(path: str | Path, series: Mapping[str, Any], result: Mapping[str, Any], fit: Any,
               label: str = "", *, figure: TouchFigure | None = None, calibration: Any = None) -> Path:
    """Write the figure of one touch (:class:`TouchFigure`).

    Parameters
    ----------
    path : str or Path
        Output file in an existing directory; its suffix picks the format
        (``.png``, ``.pdf``, ``.svg``; none: PNG). Written atomically.
    series : mapping
        The stored record with ``raw_t_s``, ``raw_T_C``, ``raw_q_W_m2``,
        ``grid_t_s``, ``grid_dT_K``, ``grid_q_W_m2``, ``T0_C`` and ``q_offset_W_m2``.
    result : mapping
        The device's answer, with :func:`host.plot_data.touch_identity`'s fields (title).
    fit : edge.estimation.result.Estimate
        Host re-estimate on the same record by the answer's method (``t_model_s``, ``fit_T_K``).
    label : str
        Scene or sample name for the title (never a port: the title identifies the measurement).
    figure : TouchFigure, optional
        A figure to draw into and keep (many touches); default: a new one, closed after.
    calibration : edge.calibration.model.ProbeCalibration, optional
        The device's calibration: a sensor-chain answer is drawn with the chain's own curve.
    """
    if figure is not None:
        return figure.draw(path, series, result, fit, label, calibration=calibration)
    with TouchFigure() as fig:
        return fig.draw(path, series, result, fit, label, calibration=calibration)


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
               label: str = "", *, calibration: Any = None) -> Path:
        """Queue one plot (arguments as :func:`plot_touch`); returns its path (written by :meth:`close`)."""
        out = Path(path)
        job = {"path": str(out), "label": label, "result": dict(result),
               "series": {k: series.get(k) for k in _SERIES_KEYS},
               "fit": None if fit is None or fit.fit_T_K is None else
               {"t_model_s": fit.t_model_s, "fit_T_K": fit.fit_T_K, "method": fit.method,
                "effusivity_W_s05_m2K": getattr(fit, "effusivity_W_s05_m2K", None),
                "effusivity_W_s05_m2K_u": getattr(fit, "effusivity_W_s05_m2K_u", None)},
               "calibration": None if calibration is None else calibration.to_json_compact()}
        try:
            self._proc.stdin.write(json.dumps(job, default=_jsonable) + "\n")
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError) as exc:
            raise PlotError(f"plot process ended before {out} was drawn: {self._why(exc)}") from None
        self._paths.append(out)
        return out

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` ran (or the process was killed)."""
        return self._closed

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
            cal = None
            if job.get("calibration") is not None:
                from edge.calibration.model import ProbeCalibration  # noqa: PLC0415

                cal = ProbeCalibration.from_json(job["calibration"])
            try:
                figure.draw(job["path"], job["series"], job["result"], fit, job["label"], calibration=cal)
                reply = {"path": job["path"]}
            except OSError as exc:
                reply = {"path": job["path"], "error": f"cannot write plot {job['path']}: {exc.strerror or exc}"}
            stdout.write(json.dumps(reply) + "\n")
            stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(_serve(sys.stdin, sys.stdout))
