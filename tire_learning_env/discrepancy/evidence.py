"""What the report says about each accepted effect: its entry, the evidence, and ambiguous alternatives.

- :func:`effect_entry`: name, parameters with units and standard errors, description and evidence
  (for IMU logs also the signature correlations with the other candidates and the effects it is
  confounded with in theory);
- :func:`evidence_of`: the statistics of the round that accepted an effect and its runner-up;
- :func:`ambiguous_alternatives`: the candidates that fit the accepted effect's round about equally
  well (the ``ambiguous`` verdict of :mod:`.workflow`).
"""

from __future__ import annotations

import math

from numpy.typing import NDArray

from .config import DiscrepancyConfig
from .criteria import acceptance_threshold
from .effects import IMU_CONFOUNDED, CandidateEffect, library_for
from .selection import SelectionResult

__all__ = ["effect_entry", "evidence_of", "ambiguous_alternatives", "selection_kind"]

#: effect pairs that e1/e2 alone cannot tell apart (the IMU can)
_EQUIVALENT_WITHOUT_IMU = {frozenset({"road_bank", "crosswind"})}


def effect_entry(
    effect: CandidateEffect, values: NDArray, stderr: NDArray, evidence: dict, channels: tuple[str, ...],
    kind: str = "camera",
) -> dict:  # fmt: skip
    entry = {
        "name": effect.name,
        "parameters": effect.as_dict(values),
        "units": effect.units_dict(),
        "standard_errors": effect.as_dict(stderr),
        "description": effect.description,
        "evidence": evidence,
    }
    if kind == "imu":
        theory = {next(iter(pair - {effect.name})): why for pair, why in IMU_CONFOUNDED.items() if effect.name in pair}
        corr = evidence.get("signature_correlation", {})
        lr = float(evidence.get("likelihood_ratio", 0.0))
        limit = float(evidence.get("acceptance_threshold", 0.0))
        # the part of the effect's likelihood ratio that another candidate cannot reproduce, to first
        # order: LR (1 - rho^2); below the acceptance threshold the log cannot tell the two apart
        separation = {n: lr * (1.0 - c * c) for n, c in corr.items()}
        close = sorted((n for n in corr if separation[n] < limit), key=lambda n: -corr[n])
        if theory:
            entry["evidence"]["confounded_in_theory_with"] = theory
        if corr:
            entry["evidence"]["separation_from"] = {
                n: separation[n] for n in sorted(corr, key=lambda n: separation[n])[:5]
            }
        if close:
            entry["evidence"]["indistinguishable_from"] = close[0] if len(close) == 1 else close
            entry["evidence"]["note"] = (
                f"on this log the signature of {effect.name} correlates at "
                + ", ".join(f"{corr[n]:.3f} with {n}" for n in close)
                + f": the part of its likelihood ratio the other cannot reproduce, LR (1 - rho^2), is below the "
                f"acceptance threshold {limit:.3g}; the data cannot tell them apart, the name is the better fit, "
                "not a proof"
            )
    if "yaw_rate" not in channels and "ay" not in channels:
        for pair in _EQUIVALENT_WITHOUT_IMU:
            if effect.name in pair:
                other = next(iter(pair - {effect.name}))
                entry["evidence"]["indistinguishable_from"] = other
                entry["evidence"]["note"] = (
                    f"without IMU channels {effect.name} and {other} act identically on e1/e2 (a constant lateral "
                    "force); the accelerometer would tell them apart"
                )
    return entry


def evidence_of(sel: SelectionResult, effect: CandidateEffect, n: int, config: DiscrepancyConfig) -> dict:
    """Why ``effect`` was accepted: its round's statistics and the runner-up."""
    for st in sel.steps:
        if st.accepted == effect.name:
            info = st.tried[effect.name]
            k = effect.n_parameters
            fitted = {name: v for name, v in st.tried.items() if v.get("fitted") and name != effect.name}
            runner = min(fitted, key=lambda nm: fitted[nm]["chi2"]) if fitted else None
            out = {
                "round": st.round,
                "chi2_before": st.chi2_before,
                "chi2_with_effect": info["chi2"],
                "likelihood_ratio": info["lr"],
                "p_value": info["p_value"],
                "delta_bic": info["delta_bic"],
                "acceptance_threshold": acceptance_threshold(k, n, config.alpha / len(st.tried)),
                "runner_up": None,
            }
            if "inflation" in info:
                out["likelihood_ratio_raw"] = info["lr_raw"]
                out["inflation"] = info["inflation"]
            if "signature_correlation" in info:
                out["signature_correlation"] = info["signature_correlation"]
            if runner is not None:
                out["runner_up"] = {
                    "name": runner,
                    "chi2": fitted[runner]["chi2"],
                    "delta_bic_vs_accepted": (fitted[runner]["chi2"] + fitted[runner]["k"] * math.log(n))
                    - (info["chi2"] + k * math.log(n)),
                }
            return out
    return {}


def ambiguous_alternatives(sel: SelectionResult, entries: list[dict], n: int, config: DiscrepancyConfig) -> list[dict]:
    """The accepted effect with candidates that fit its round about equally well, best first (else empty).

    An alternative qualifies when it was fitted in the round that accepted an effect, passed the
    acceptance test itself, is not accepted in the end, and its BIC is within ``config.ambiguity_bic``
    of the accepted effect's. Each entry: name, parameters, chi2, BIC difference to the best, evidence.
    """
    final = {e["name"] for e in entries}
    for st in sel.steps:
        if st.accepted is None or st.accepted not in final:
            continue
        best = st.tried[st.accepted]
        level = config.alpha / len(st.tried)
        bic_best = best["chi2"] + best["k"] * math.log(n)
        group = []
        for name, info in st.tried.items():
            if name == st.accepted or name in final or not info.get("fitted"):
                continue
            bic = info["chi2"] + info["k"] * math.log(n)
            if info["p_value"] < level and info["delta_bic"] < 0.0 and bic - bic_best < config.ambiguity_bic:
                group.append((bic - bic_best, name, info))
        if not group:
            continue
        entry = next(e for e in entries if e["name"] == st.accepted)
        out = [{
            "name": st.accepted, "parameters": entry["parameters"], "units": entry["units"],
            "standard_errors": entry["standard_errors"], "delta_bic_to_best": 0.0, "chi2": best["chi2"],
            "likelihood_ratio": best["lr"], "p_value": best["p_value"], "description": entry["description"],
        }]  # fmt: skip
        for dbic, name, info in sorted(group, key=lambda g: g[0]):
            eff = next(c for c in library_for(selection_kind(sel)) if c.name == name)
            out.append({
                "name": name, "parameters": info["parameters"], "units": eff.units_dict(),
                "delta_bic_to_best": float(dbic), "chi2": info["chi2"], "likelihood_ratio": info["lr"],
                "p_value": info["p_value"], "description": eff.description,
            })  # fmt: skip
        return out
    return []


def selection_kind(sel: SelectionResult) -> str:
    """Log kind of a selection (the IMU model state has 2 entries, the camera model 4)."""
    return "imu" if sel.nominal.x0.shape[1] == 2 else "camera"
