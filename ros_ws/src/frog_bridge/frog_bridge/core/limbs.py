"""The order in which the bridge writes a primitive's limbs (the table is frog_common's).

The authors' executor writes each pulse's limb ids in the primitive's bit order, FR before
FL and BL before BR; the relay and firmware accept either, but the bridge sends what the
robot was run with.
"""

from __future__ import annotations

from frog_common.primitives import LIMB_IDS, PRIMITIVE_BIT_ORDER, PRIMITIVE_NAMES, primitive_limbs


def primitive_pairs(primitive_id: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Limb ids of the front and rear pulses of a primitive, in the authors' write order.

    Parameters
    ----------
    primitive_id : int
        0-8 (A-I).

    Returns
    -------
    (front, rear) : tuple of tuple of int
        An empty tuple means that pair sends nothing.

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
    front, rear = primitive_limbs(primitive_id)
    return tuple(tuple(LIMB_IDS[n] for n in sorted(pair, key=PRIMITIVE_BIT_ORDER.index)) for pair in (front, rear))
