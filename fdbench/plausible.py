"""What a body's constants can plausibly be: a ``--model``/``--plant`` value outside is most likely a
unit mistyped (centimetres for metres, grams for kilograms); runs that fail say so."""

from __future__ import annotations

# What a human arm's constants can be (SI units): a value outside is most likely a unit mistyped
# (centimetres for metres, grams for kilograms). Warned about, not refused: a study may want it.
PLAUSIBLE = {
    "L12": (0.05, 1.0, "m", "a forearm's length"), "L1G": (0.01, 1.0, "m", "a centre of mass's distance"),
    "L01": (0.05, 1.0, "m", "an upper arm's length"), "L0G": (0.01, 1.0, "m", "a centre of mass's distance"),
    "m": (0.1, 20.0, "kg", "a forearm's mass"), "m0": (0.1, 20.0, "kg", "an upper arm's mass"),
    "I1": (1e-4, 2.0, "kg m^2", "a forearm's inertia about the elbow"),
    "I0": (1e-4, 2.0, "kg m^2", "an upper arm's inertia about the shoulder"),
    "F_ext": (-1000.0, 1000.0, "N", "a load held in the hand"), "g": (0.0, 30.0, "m/s^2", "gravity"),
}


def implausible(changes) -> list[str]:
    """One text per (key, value) pair of ``changes`` outside what a human arm can be (PLAUSIBLE),
    naming the value and its unit: 'L12 = 30 m is implausible (a forearm's length is 0.05 to 1 m;
    centimetres typed for metres?)'."""
    texts = []
    for key, value in dict(changes).items():
        if key not in PLAUSIBLE or not isinstance(value, (int, float)):
            continue
        low, high, unit, what = PLAUSIBLE[key]
        if not low <= value <= high:
            hint = "; centimetres typed for metres?" if unit == "m" and 100 * low <= value <= 100 * high else ""
            hint = "; grams typed for kilograms?" if unit == "kg" and 1000 * low <= value <= 1000 * high else hint
            texts.append(f"{key} = {value:g} {unit} is implausible ({what} is {low:g} to {high:g} {unit}{hint})")
    return texts
