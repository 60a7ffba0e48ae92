"""Plots of scripts/bench_iso_accuracy.sh: residual vs projection order, time vs residual."""
import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

out = sys.argv[1]


def rows(name):
    with open(f"{out}/{name}") as f:
        return list(csv.DictReader(f))


order = rows("order.csv")
fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
for ax, ds in zip(axes, ["sinc", "quartic"]):
    for polish, style in [("false", "--"), ("true", "-")]:
        sel = [r for r in order if r["dataset"] == ds and r["polish"] == polish]
        x = [int(r["order"]) for r in sel]
        label = "projection root" if polish == "false" else "polished on true field"
        ax.semilogy(x, [max(float(r["rms_residual_rel"]), 1e-17) for r in sel], "o" + style,
                    label=f"RMS, {label}")
        ax.semilogy(x, [max(float(r["max_residual_rel"]), 1e-17) for r in sel], "s" + style,
                    label=f"max, {label}")
    ax.set_title(f"nk-{ds}")
    ax.set_xlabel("projection order")
    ax.grid(True, which="both", alpha=0.3)
axes[0].set_ylabel("residual / field range")
axes[1].legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{out}/residual_vs_order.png", dpi=120)

acc = rows("accuracy.csv")
fig, ax = plt.subplots(figsize=(6, 4.2))
for ds, marker in [("sinc", "o"), ("quartic", "s")]:
    for polish, color in [("false", "tab:orange"), ("true", "tab:blue")]:
        sel = [r for r in acc if r["dataset"] == ds and r["polish"] == polish]
        ax.loglog([max(float(r["max_residual_rel"]), 1e-17) for r in sel],
                  [float(r["render_s"]) for r in sel], marker, color=color, alpha=0.7,
                  label=f"nk-{ds}, polish={polish}")
ax.set_xlabel("max residual / field range")
ax.set_ylabel("render time (s)")
ax.grid(True, which="both", alpha=0.3)
ax.legend(fontsize=7)
fig.tight_layout()
fig.savefig(f"{out}/time_vs_residual.png", dpi=120)
print(f"wrote {out}/residual_vs_order.png and {out}/time_vs_residual.png")
