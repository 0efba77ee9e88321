"""The frog's four limbs and nine motion primitives (DESIGN.md, seed 000 "Motion planning").

Limb ids are the robot firmware's and ``LimbActivation.msg``'s: FL 0, FR 1, BL 2, BR 3.
A primitive's bits are [FR, FL, BL, BR] as in the authors' control code; its front limbs
fire first, its rear limbs one pulse later. Ids 0-8 are A-I as in ``Primitive.msg``
(tests/test_vocabulary.py checks both messages' constants against this table).
"""

from __future__ import annotations

import numbers

LIMB_NAMES = ('FL', 'FR', 'BL', 'BR')          # index = limb id
LIMB_IDS = {name: i for i, name in enumerate(LIMB_NAMES)}
FRONT_LIMBS = ('FL', 'FR')
REAR_LIMBS = ('BL', 'BR')
PRIMITIVE_BIT_ORDER = ('FR', 'FL', 'BL', 'BR')
PRIMITIVE_BITS = {'A': '1100', 'B': '1111', 'C': '0111', 'D': '1011', 'E': '0110',
                  'F': '1001', 'G': '0100', 'H': '1000', 'I': '0000'}
PRIMITIVE_NAMES = tuple(PRIMITIVE_BITS)       # index = primitive id: 'A'..'I'
PRIMITIVE_IDS = {name: i for i, name in enumerate(PRIMITIVE_NAMES)}
NO_ACTION = 'I'                               # fires nothing: what a planner sends when it may not act


def primitive_name(primitive) -> str:
    """A primitive given as id 0-8 (or its digits) or name 'A'-'I' (any case), as its name.

    Raises
    ------
    ValueError
        If the id is out of range 0-8 or the name unknown.

    Examples
    --------
    >>> primitive_name(1), primitive_name('e'), primitive_name('8')
    ('B', 'E', 'I')
    """
    if isinstance(primitive, numbers.Integral) and not isinstance(primitive, bool):
        if not 0 <= int(primitive) < len(PRIMITIVE_NAMES):
            raise ValueError(f'primitive id {primitive} is out of range 0-8')
        return PRIMITIVE_NAMES[int(primitive)]
    name = str(primitive).strip().upper()
    if name.isdigit():
        return primitive_name(int(name))
    if name not in PRIMITIVE_BITS:
        raise ValueError(f"primitive {primitive!r} is unknown; expected an id 0-8 or a name A-I")
    return name


def primitive_id(primitive) -> int:
    """The id 0-8 of a primitive given as id or name."""
    return PRIMITIVE_IDS[primitive_name(primitive)]


def primitive_limbs(primitive) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Limbs fired by a primitive: (front limbs, fired first; rear limbs, one pulse later),
    each in limb-id order (FL, FR / BL, BR).

    >>> primitive_limbs('E')
    (('FL',), ('BL',))
    """
    bits = PRIMITIVE_BITS[primitive_name(primitive)]
    fired = [limb for limb, bit in zip(PRIMITIVE_BIT_ORDER, bits) if bit == '1']
    return tuple(x for x in FRONT_LIMBS if x in fired), tuple(x for x in REAR_LIMBS if x in fired)


def limb_label(limb_ids) -> str:
    """``'FR+FL'`` style label of limb ids (``'none'`` when empty; ``'?7'`` for an unknown id)."""
    return '+'.join(LIMB_NAMES[i] if 0 <= i < len(LIMB_NAMES) else f'?{i}' for i in limb_ids) or 'none'
