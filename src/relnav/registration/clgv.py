"""CLGV baseline of Paper 1 §4.5 as a registration method: ``clgv:<descriptor>``.

Paper 1 §4.5 describes "Correspondence by Local and Global Voting" (Buch et al. 2014) as four
steps: feature description, correspondence refinement via GCC and RANSAC, and SVD. Here:
descriptor → exact NN matching (``τ``) → the ``clgv`` grouper
(:class:`relnav.matching.grouping.ClgvGrouper`: local voting with the GCC distance-preservation
test, global voting with RANSAC hypotheses; ALGORITHMS §B.4, **[interpretation]** — the original
paper is not in the corpora) → the ``svd`` estimator (Kabsch/Umeyama). It is
:class:`~relnav.registration.feature.FeatureRegistration` with grouper ``"clgv"`` and estimator
``"svd"``; every option of that class applies (``grouper_options={"seed": 1, "k": 10, ...}``,
``tau``, ``keypoints``, ...). The CLGV voting is seeded (``grouper_options["seed"]``, default 0)
and its diagnostics (seed, hypotheses) are in ``result.info["grouper"]``.

Method strings: ``clgv`` (HoD-S, Paper 1's best descriptor), ``clgv:fpfh``, ``clgv:shot``, ...
"""

from __future__ import annotations

from typing import Any

from relnav.errors import ConfigError
from relnav.registration.base import register_method
from relnav.registration.feature import CloudFeatures, FeatureRegistration
from relnav.registration.result import RegistrationResult

__all__ = ["CLGVRegistration"]


class CLGVRegistration(FeatureRegistration):
    """Descriptor → NN → CLGV voting → SVD (Paper 1 §4.5).

    Parameters
    ----------
    descriptor : str
        Registered descriptor name (default ``hods``).
    estimator : str
        Estimator after the voting (Paper 1: ``svd``).
    **options
        Any other :class:`~relnav.registration.feature.FeatureRegistration` option.
    """

    def __init__(self, descriptor: str = "hods", *, estimator: str = "svd", **options: Any) -> None:
        if "grouper" in options:
            raise ConfigError("clgv: the grouper is fixed to 'clgv'; use feature:<d>+<g>+<e>")
        super().__init__(descriptor, "clgv", estimator, **options)
        self.name = f"clgv:{descriptor}" if estimator == "svd" else f"clgv:{descriptor}+{estimator}"

    def register_prepared(
        self, source: CloudFeatures, target: CloudFeatures, *, init: Any = None
    ) -> RegistrationResult:
        """As :meth:`FeatureRegistration.register_prepared`; adds the voting diagnostics."""
        result = super().register_prepared(source, target, init=init)
        result.info["grouper"] = dict(getattr(self.grouper, "info", {}) or {})
        result.info["method"] = self.name
        return result


def _parse(spec: str | None) -> tuple[str, str]:
    if not spec:
        return "hods", "svd"
    parts = [p.strip().lower() for p in spec.split("+")]
    if len(parts) == 1 and parts[0]:
        return parts[0], "svd"
    if len(parts) == 2 and all(parts):
        return parts[0], parts[1]
    raise ConfigError(
        f"clgv method spec {spec!r} must be '<descriptor>' or '<descriptor>+<estimator>' "
        "(e.g. clgv:hods, clgv:fpfh+kalman)"
    )


@register_method(
    "clgv",
    "Paper 1 §4.5 baseline: descriptors → NN → local+global voting (GCC test + RANSAC) → SVD",
    examples=["clgv:hods", "clgv:fpfh", "clgv:shot"],
)
def _make_clgv(spec: str | None, **options: Any) -> CLGVRegistration:
    descriptor, estimator = _parse(spec)
    return CLGVRegistration(descriptor, estimator=estimator, **options)
