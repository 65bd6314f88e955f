"""
# A small sweep: when does the carrier leave the wall?

On a vibrating track a carrier resting on the inner wall stays there only while the load
presses it harder than the wall accelerates away: `a_p >= h_a omega_h^2`, with
`a_p = (T1 cos(phi) + m r_c omega^2) / m` (see the model page, section 7). This sweeps the
vibration amplitude `h_a` at the paper's horn-gear speed with the batch engine and counts the
impacts once the first ones have died down.
"""

# %%
import matplotlib.pyplot as plt
import numpy as np

import braidsim
from braidsim.analysis import contact_loss_bound
from braidsim.batch import simulate_batch

bound = contact_loss_bound("paper-3.3")
h_crit = bound["critical_amplitude"]
a_p = bound["pressing_acceleration"]
print(f"a_p = {a_p:.4g} m/s^2; contact-loss amplitude h_a = {h_crit * 1e3:.4f} mm")

# %%
# Start the carrier at rest on the wall, and run 0.5 s per amplitude; the metrics cover the
# last 0.2 s.
amplitudes = np.linspace(0.04e-3, 0.16e-3, 7)
sets = [{"track.vibration_amplitude": float(h)} for h in amplitudes]
start = {"initial.x": 0.0, "initial.vx": 0.0}
sc = braidsim.load_scenario("paper-3.3", overrides=start)
batch = simulate_batch(sc, sets, duration=0.5, window=(0.3, 0.5))
table = batch.to_dataframe()
table["h_a [mm]"] = amplitudes * 1e3
table["regime"] = batch.regime_labels()
table["track_impacts"] = table["track_inner_impacts"] + table["track_outer_impacts"]
print(table[["h_a [mm]", "regime", "track_impacts"]])

# %%
fig, ax = plt.subplots(figsize=(6.4, 3.6))
ax.plot(amplitudes * 1e3, table["track_impacts"], "o-")
ax.axvline(h_crit * 1e3, color="k", ls="--", label="a_p = h_a omega_h^2")
ax.set_xlabel("track vibration amplitude h_a [mm]")
ax.set_ylabel("track impacts in the last 0.2 s")
ax.legend()
fig.tight_layout()
