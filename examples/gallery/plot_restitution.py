"""
# The restitution each contact law really gives

Every law has the form `F = K p^n (1 + D(c_r) pdot / v0)`, and one free impact then
restitutes `e` with `1 - D e = (1 + D) exp(-D (1 + e))`, whatever the mass, stiffness,
exponent and approach speed. Here the exact relation is drawn for every law against the
nominal `c_r` it is given, and checked against simulated impacts.
"""

# %%
import matplotlib.pyplot as plt
import numpy as np

from braidsim.contact import effective_restitution, get_law, law_names
from braidsim.impact import single_impact

c_values = np.linspace(0.05, 1.0, 40)
fig, ax = plt.subplots(figsize=(6.4, 4.2))
for name in law_names():
    law = get_law(name)
    if not law.dissipative:
        continue
    e = [effective_restitution(law.damping_factor(float(c))) for c in c_values]
    ax.plot(c_values, e, label=name)
ax.plot([0, 1], [0, 1], "k--", lw=1, label="e = c_r")
ax.set_xlabel("nominal coefficient of restitution c_r [-]")
ax.set_ylabel("effective restitution e [-]")
ax.legend(fontsize=7)
ax.set_title("One impact: effective against nominal restitution")
fig.tight_layout()

# %%
# A simulated impact of the paper's carrier (1.2 kg at 0.5 m/s on the calibrated track
# stiffness) for three laws at c_r = 5/9, beside the exact relation.
for name in ("hunt_crossley", "flores", "carvalho_martins"):
    sim = single_impact(model=name, restitution=5 / 9, velocity=0.5)
    exact = effective_restitution(get_law(name).damping_factor(5 / 9))
    print(
        f"{name:18s} simulated e = {sim['effective_restitution']:.6f}, exact {exact:.6f}, "
        f"peak force {sim['max_force']:.0f} N"
    )
