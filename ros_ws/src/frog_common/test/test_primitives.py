"""The primitive and limb table against the paper's and the authors' definitions."""

import pytest

from frog_common.primitives import (LIMB_IDS, LIMB_NAMES, NO_ACTION, PRIMITIVE_BITS, PRIMITIVE_IDS,
                                    PRIMITIVE_NAMES, limb_label, primitive_id, primitive_limbs,
                                    primitive_name)

# seed 000, Fig. 4a / the authors' planner.py: which limbs each primitive fires
FIRES = {'A': {'FR', 'FL'}, 'B': {'FR', 'FL', 'BL', 'BR'}, 'C': {'FL', 'BL', 'BR'},
         'D': {'FR', 'BL', 'BR'}, 'E': {'FL', 'BL'}, 'F': {'FR', 'BR'}, 'G': {'FL'}, 'H': {'FR'},
         'I': set()}


def test_limb_ids_are_the_firmwares():
    assert LIMB_IDS == {'FL': 0, 'FR': 1, 'BL': 2, 'BR': 3}
    assert [LIMB_NAMES[i] for i in range(4)] == ['FL', 'FR', 'BL', 'BR']


@pytest.mark.parametrize('name', list(FIRES))
def test_each_primitive_fires_its_limbs_front_first(name):
    front, rear = primitive_limbs(name)
    assert set(front) | set(rear) == FIRES[name]
    assert all(x[0] == 'F' for x in front) and all(x[0] == 'B' for x in rear)
    assert primitive_limbs(PRIMITIVE_IDS[name]) == (front, rear)


def test_ids_names_round_trip_and_bad_input_is_named():
    assert PRIMITIVE_NAMES == tuple('ABCDEFGHI') and len(PRIMITIVE_BITS) == 9
    for i, name in enumerate(PRIMITIVE_NAMES):
        assert primitive_name(i) == name == primitive_name(name.lower()) == primitive_name(str(i))
        assert primitive_id(name) == i
    assert primitive_limbs(NO_ACTION) == ((), ())
    for bad in (9, -1, 'J', '', True):
        with pytest.raises(ValueError, match='primitive'):
            primitive_name(bad)


def test_limb_label():
    assert limb_label([1, 0]) == 'FR+FL'
    assert limb_label([]) == 'none'
    assert limb_label([7]) == '?7'
