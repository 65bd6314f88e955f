"""
# Section 3.1 of the paper: impacts without track vibration

The carrier starts on the inner wall (x0 = 0) moving outward at 0.5 m/s, crosses the
track's 3 mm gap, hits the outer wall, crosses back, and bounces on the inner wall until it
rests there under the constant load
(yarn tension plus centrifugal force). This is the paper's Figs. 3-6 and the Hunt-Crossley
row of its Table 1; `braidsim paper` compares every number, this example shows the run.
"""

# %%
# Run the built-in scenario for 0.2 s: the bounces are over by 0.13 s.
import matplotlib.pyplot as plt

import braidsim
from braidsim.plotting import plot_quantity

res = braidsim.simulate("paper-3.1", duration=0.2)
summary = res.summary()
for quantity in ("depth", "stiffness_force", "damping_force"):
    lo, hi = summary["x"][quantity]
    print(f"{quantity:16s} min {lo:11.5g}  max {hi:11.5g}")

# %%
# The impact table: one row per contact, with the approach speed latched at onset (the `v0`
# of the damping term), the rebound speed, the peak force and the deepest penetration. The
# ratio of rebound to approach speed is the restitution the Hunt-Crossley law gives at the
# paper's c_r = 5/9: about 0.69, not 0.56 (see the contact-laws page).
imp = res.impacts.assign(max_depth_mm=res.impacts["max_depth"] * 1e3)
print(imp[["t", "wall", "velocity", "rebound_velocity", "peak_force", "max_depth_mm"]].round(4))
print("rebound / approach:", (imp["rebound_velocity"] / imp["velocity"]).round(3).tolist()[:4])

# %%
# The displacement with the walls (fixed here: no vibration), and the stiffness-related force
# F_kg, signed as in the paper (negative on the inner wall), drawn by `braidsim.plotting`.
fig, (ax_x, ax_f) = plt.subplots(2, 1, figsize=(6.4, 6.0), sharex=True, layout="constrained")
plot_quantity(res, "x", ax=ax_x)
plot_quantity(res, "stiffness_force", ax=ax_f)

# %%
# The impact sequence: the peak force of each impact falls with its approach speed.
fig, ax = plt.subplots(figsize=(6.4, 3.6), layout="constrained")
for wall, marker in (("outer", "^"), ("inner", "o")):
    rows = imp[imp["wall"] == wall]
    ax.plot(rows["velocity"], rows["peak_force"], marker, ls="none", label=f"{wall} wall")
ax.set_xlabel("approach speed v0 [m/s]")
ax.set_ylabel("peak contact force [N]")
ax.legend()
