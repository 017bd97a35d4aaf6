"""The report a student reads after `identify`: Markdown with a table of what changed (and how
sure the fit is), RMS errors before and after per bag and per joint, and for each bag a PNG of
recorded vs simulated trajectories, before and after, with the residual beside each joint."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mexone.identify.patch import value_text
from mexone.identify.problem import Prediction
from mexone.identify.session import Result

__all__ = ["markdown", "plot_bag", "figure_name", "MAX_POINTS"]

MAX_POINTS = 2000  # per plotted line: more shows nothing at a report's width


def figure_name(prediction: Prediction) -> str:
    return Path(prediction.experiment.name).stem + ".png"


def _mrad(value: float) -> str:
    return f"{value * 1000:.3g}"


def markdown(result: Result, outputs: dict[str, str], figures: bool = True) -> str:
    """The report's text; `outputs` names the other files written (what -> file name);
    `figures`: a PNG per bag was written (not after a stop)."""
    fit = result.fit
    lines = ["# mexone identify", ""]
    fitted = ", ".join(e.name for e in result.experiments)
    lines.append(f"Fitted {len(fit.unknowns)} parameters on {fitted} "
                 f"({fit.iterations} iterations, {fit.evaluations} evaluations, "
                 f"{fit.seconds:.1f} s)" + (f"; validated on {', '.join(e.name for e in result.validation)}"
                                             if result.validation else "") + ".")
    if fit.interrupted:
        lines += ["", "**Interrupted**: these are the best values found before Ctrl-C or SIGTERM, "
                      "without confidence intervals" + ("." if figures else " or plots.")]
    where = "the held-out bags" if result.held_out else "the fitted bags"
    ratio = result.rms_before / result.rms_after if result.rms_after > 0 else float("inf")
    lines += ["", f"RMS joint error on {where}: **{_mrad(result.rms_before)} mrad before, "
                  f"{_mrad(result.rms_after)} mrad after** ({ratio:.3g}x smaller).", ""]
    for what, name in outputs.items():
        lines.append(f"- {what}: `{name}`")
    lines += ["", "## Parameters", "",
              "| parameter | unit | model | identified | 95% interval (+-) | change |",
              "|---|---|---|---|---|---|"]
    for i, u in enumerate(fit.unknowns):
        old, new = fit.nominal[i], fit.values[i]
        half = "" if fit.halfwidth is None else value_text(fit.halfwidth[i])
        change = f"{(new / old - 1) * 100:+.1f}%" if old else "new"
        lines.append(f"| {u.name} | {u.unit} | {value_text(old)} | {value_text(new)} | {half} | "
                     f"{change} |")
    if fit.correlation is not None:
        strong = _strong_correlations(result)
        if strong:
            lines += ["", "Strongly correlated (|r| > 0.9: the data tells their sum or difference "
                          "better than each; excite more, or fix one):", ""]
            lines += [f"- {a} and {b}: r = {r:+.2f}" for a, b, r in strong]
    lines += ["", "## RMS joint error (mrad)", "", "| bag | role | before | after |",
              "|---|---|---|---|"]
    n = len(result.experiments)
    for k, (b, a) in enumerate(zip(result.before, result.after, strict=True)):
        role = "fitted" if k < n else "held out"
        lines.append(f"| {b.experiment.name} | {role} | {_mrad(b.rms())} | {_mrad(a.rms())} |")
    for b, a in zip(result.before, result.after, strict=True):
        figure = [f"![{b.experiment.name}]({figure_name(b)})", ""] if figures else []
        lines += ["", f"## {b.experiment.name}", "", *figure, "| joint | before | after |",
                  "|---|---|---|"]
        before, after = b.rms_per_joint(), a.rms_per_joint()
        lines += [f"| {j} | {_mrad(before[j])} | {_mrad(after[j])} |" for j in before]
    if result.notes:
        lines += ["", "## Notes", ""] + [f"- {note}" for note in result.notes]
    return "\n".join(lines) + "\n"


def _strong_correlations(result: Result, limit: float = 0.9) -> list[tuple[str, str, float]]:
    corr, names = result.fit.correlation, [u.name for u in result.fit.unknowns]
    out = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > limit:
                out.append((names[i], names[j], float(corr[i, j])))
    return sorted(out, key=lambda x: -abs(x[2]))[:20]


def plot_bag(before: Prediction, after: Prediction, path: Path) -> None:
    """One row per joint: recorded, simulated before and after (left), residuals (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    e = before.experiment
    t = e.times
    every = max(1, len(t) // MAX_POINTS)
    rows = len(e.joints)
    height = 1.7 * rows + 0.8
    fig, axes = plt.subplots(rows, 2, figsize=(12, height), sharex=True, squeeze=False,
                             gridspec_kw={"width_ratios": (3, 2)})
    for i, joint in enumerate(e.joints):
        ok = np.isfinite(e.measured[:, i])
        ts, rec = t[ok][::every], e.measured[ok, i][::every]
        qb, qa = before.q[ok, i][::every], after.q[ok, i][::every]
        left, right = axes[i]
        left.plot(ts, rec, color="black", lw=1.4, label="recorded")
        left.plot(ts, qb, color="tab:red", lw=0.9, ls="--", label="model")
        left.plot(ts, qa, color="tab:blue", lw=0.9, label="identified")
        left.set_ylabel(f"{joint}\n(rad)", fontsize=8)
        right.plot(ts, (qb - rec) * 1000, color="tab:red", lw=0.8, label="model")
        right.plot(ts, (qa - rec) * 1000, color="tab:blue", lw=0.8, label="identified")
        right.axhline(0.0, color="grey", lw=0.5)
        right.set_ylabel("residual\n(mrad)", fontsize=8)
        for ax in (left, right):
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper right", ncol=3)
    axes[0, 1].legend(fontsize=7, loc="upper right", ncol=2)
    axes[-1, 0].set_xlabel("time (s)")
    axes[-1, 1].set_xlabel("time (s)")
    fig.suptitle(f"{e.name}: RMS {_mrad(before.rms())} -> {_mrad(after.rms())} mrad", fontsize=10)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 1.0 - 0.5 / height))
    fig.savefig(path, dpi=80)
    plt.close(fig)
