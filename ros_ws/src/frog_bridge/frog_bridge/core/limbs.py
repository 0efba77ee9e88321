"""Limb ids and the nine motion primitives of the frog (DESIGN.md, seed 000 "Motion planning").

Limb ids are the robot firmware's: FL 0, FR 1, BL 2, BR 3. A primitive's bits are
[FR, FL, BL, BR]; the front pair fires first, the rear pair one pulse later.
"""

from __future__ import annotations

LIMB_IDS = {"FL": 0, "FR": 1, "BL": 2, "BR": 3}
LIMB_NAMES = {v: k for k, v in LIMB_IDS.items()}
FRONT_LIMBS = (LIMB_IDS["FR"], LIMB_IDS["FL"])
REAR_LIMBS = (LIMB_IDS["BL"], LIMB_IDS["BR"])

PRIMITIVE_NAMES = "ABCDEFGHI"
# bits [FR, FL, BL, BR] from the authors' control code
PRIMITIVE_BITS = {"A": "1100", "B": "1111", "C": "0111", "D": "1011", "E": "0110",
                  "F": "1001", "G": "0100", "H": "1000", "I": "0000"}
_BIT_LIMBS = (LIMB_IDS["FR"], LIMB_IDS["FL"], LIMB_IDS["BL"], LIMB_IDS["BR"])


def primitive_pairs(primitive_id: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Limb ids of the front and rear pulses of a primitive.

    Parameters
    ----------
    primitive_id : int
        0-8 (A-I).

    Returns
    -------
    (front, rear) : tuple of tuple of int
        Limb ids in the order the authors' code writes them (FR before FL, BL before BR);
        an empty tuple means that pair sends nothing.

    Raises
    ------
    ValueError
        If the id is not in 0-8.

    Examples
    --------
    >>> primitive_pairs(0)      # A = 1100
    ((1, 0), ())
    """
    if not (isinstance(primitive_id, int) and 0 <= primitive_id < len(PRIMITIVE_NAMES)):
        raise ValueError(f"primitive id {primitive_id!r} is out of range 0-8")
    bits = PRIMITIVE_BITS[PRIMITIVE_NAMES[primitive_id]]
    on = [limb for bit, limb in zip(bits, _BIT_LIMBS) if bit == "1"]
    return tuple(i for i in on if i in FRONT_LIMBS), tuple(i for i in on if i in REAR_LIMBS)


def limb_names(limbs) -> str:
    """``"FR+FL"`` style label of limb ids (``"none"`` when empty)."""
    return "+".join(LIMB_NAMES.get(i, f"?{i}") for i in limbs) or "none"
