"""errors.png keeps the errors readable under a step envelope that grows far above them
(issue 42: a map-based navigator's errors stay bounded while its accumulated step σ grows)."""

from __future__ import annotations

import numpy as np

import relnav.eval.plots as plots


def _capture(monkeypatch):  # type: ignore[no-untyped-def]
    figs = []
    monkeypatch.setattr(plots, "save_png", lambda fig, path, dpi, **kw: figs.append(fig) or path)
    return figs


def _poses(n: int, err: float) -> tuple[np.ndarray, np.ndarray]:
    gt = np.repeat(np.eye(4)[None], n, axis=0)
    gt[:, 0, 3] = np.arange(n, dtype=float)
    est = gt.copy()
    est[1:, 1, 3] = err  # a constant 'err' m offset after the start
    return gt, est


def test_envelope_far_above_the_errors_is_clipped_and_said(monkeypatch, tmp_path) -> None:
    figs = _capture(monkeypatch)
    gt, est = _poses(20, 0.05)
    sig = np.full((20, 2), [0.5, 1.0])  # 3σ reaches ~6.5 m: > 100x the error
    plots.plot_errors(tmp_path / "e.png", gt, {"a": est}, step_sigmas={"a": sig})
    top = figs[0].axes[0].get_ylim()[1]
    assert plots.ENVELOPE_CLIP * 0.05 <= top <= 1.1 * plots.ENVELOPE_CLIP * 0.05  # not 6.5 m
    texts = [t.get_text() for t in figs[0].legends[0].get_texts()]
    assert any("off scale" in t and "6.54 m" in t for t in texts), texts


def test_envelope_near_the_errors_sets_the_scale(monkeypatch, tmp_path) -> None:
    figs = _capture(monkeypatch)
    gt, est = _poses(20, 0.05)
    sig = np.full((20, 2), [0.005, 0.01])  # 3σ reaches ~0.065 m: the same order
    plots.plot_errors(tmp_path / "e.png", gt, {"a": est}, step_sigmas={"a": sig})
    top = figs[0].axes[0].get_ylim()[1]
    assert top >= plots.step_envelope(sig)[-1, 0]  # the whole envelope is visible
    texts = [t.get_text() for t in figs[0].legends[0].get_texts()]
    assert not any("off scale" in t for t in texts)


def test_a_name_matplotlib_would_hide_is_still_in_the_legend(monkeypatch, tmp_path) -> None:
    """matplotlib drops legend labels starting with ``_`` (and then failed on an empty legend):
    a method named ``_Mine`` is drawn and named ``Mine``."""
    figs = _capture(monkeypatch)
    gt, est = _poses(8, 0.05)
    sig = np.full((8, 2), [0.01, 0.1])
    plots.plot_errors(tmp_path / "e.png", gt, {"_Mine": est}, step_sigmas={"_Mine": sig})
    texts = [t.get_text() for t in figs[0].legends[0].get_texts()]
    assert "Mine" in texts and any(t.startswith("Mine: 3σ") for t in texts), texts
