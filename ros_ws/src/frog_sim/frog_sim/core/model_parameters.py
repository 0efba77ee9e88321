"""Every physical parameter of the frog model, in one place, with its source.

All values are SI (m, kg, s, N, Pa). Paper = seed ``000_be5af640e730d35d.txt``
("Energy, Forces, and Equations of Motion", "Hydrodynamic Characterization",
"Robot Electronics", Fig. 2). Where the paper is silent, the value is chosen from
the physics of the described materials and the reasoning is written next to it;
``PARAMETER_SOURCES`` holds the same text for reports (``frog-sim params``).

Geometry (resolution of Fig. 2b)
--------------------------------
Fig. 2b gives L_o = 90 mm, L_i = 35 mm, H_f = 35 mm, H_a = 24 mm without a legend.
We read L_o as the side of the square body (the centre line of the four stiff body
rods, limbs attached at the corners, paper: "each joint node at the corners ... is
connected to three different nodes") and L_i as the length of each limb. This is the
only reading consistent with the paper's node count: at dl = L_o / 23 = 3.91 mm the
body ring has 92 nodes and each limb adds 9, giving exactly N = 128 (paper: "dl ~ 4 mm
resulting in N_total = 128 nodes"). H_f and H_a are read as the heights of the front
and rear sides of the body: they set the body's drag (eq. 1) and added mass
(eq. 3) diameter, linear in between along the sides.

Fluid model (``frog-sim fidelity``): the body's sections are its height
instead of a 4 mm rod, the limbs are flat strips of a calibrated width, added mass is
lumped with its direction average, and the sense of the relaxed curl, the front/rear
root angles and C_bn are jointly calibrated against the hardware transitions and all
experiment speeds (``frog-sweep calibrate``). ``frog_sim.calibration.LEGACY_MODEL``
(``body_fluid_section='rod'``, ``limb_fluid_width=0.004``, ``added_mass_lumping='normal'``,
``limb_curl_direction='backward'``, ``limb_root_angle_deg=-75``,
``front_root_angle_offset_deg=0``, ``body_drag_normal=0.8``) restores the earlier model.

Turns over several periods: a linear damping lumped on the rigid body (surge X_u, sway
Y_v, yaw N_r; ``core/body_damping.py``), the limbs' normal drag coefficient of a flat strip
and the friction at the waterline (``core/waterline_friction.py``: what stops a turn within
the period, so that a sustained turn does not gain turn period after period), calibrated on
N = 1..4 period replays of all nine hardware runs with every other target
(``frog-sweep calibrate-replays``; record in ``frog_sim/data/replay_calibration.json``).
"""
from __future__ import annotations

from dataclasses import dataclass, fields

from frog_common.settings import Settings, check, setting

import numpy as np

#: Density of water [kg/m^3] (paper, eq. 1-4: rho_f = 1000).
WATER_DENSITY = 1000.0
#: Density of EGaIn liquid metal [kg/m^3] (Dickey, Adv. Funct. Mater. 2008: 6.25 g/cm^3).
EGAIN_DENSITY = 6250.0
#: Density of the platinum-cure silicone of the limb layers [kg/m^3]
#: (Smooth-On Ecoflex/Dragon Skin data sheets: 1.07-1.08 g/cm^3).
SILICONE_DENSITY = 1080.0


@dataclass(frozen=True)
class FrogParameters(Settings):
    """Physical and numerical parameters of the frog robot model (SI units).

    Attributes are documented in ``PARAMETER_SOURCES``; use :meth:`replace` to
    derive variants (``params.replace(egain_vol_pct=30)``).
    """

    # --- geometry (paper Fig. 2b; see module docstring) ---
    # L_o [m]
    body_side_length: float = setting(0.090,
                                      'paper Fig. 2b L_o = 90 mm, read as body square side (gives N = 128)',
                                      min=0.03, max=0.3, unit='m')
    # L_i [m]
    limb_length: float = setting(0.035,
                                 'paper Fig. 2b L_i = 35 mm, read as limb length (gives N = 128)',
                                 min=0.01, max=0.1, unit='m')
    # H_f [m]: height of the front side (body_fluid_section='height')
    front_dimension_hf: float = setting(0.035,
                                        'paper Fig. 2b H_f = 35 mm: height of the front side (body drag, added mass)',
                                        min=0.005, max=0.1, unit='m')
    # H_a [m]: height of the rear side
    aft_dimension_ha: float = setting(0.024,
                                      'paper Fig. 2b H_a = 24 mm: height of the rear side (body drag, added mass)',
                                      min=0.005, max=0.1, unit='m')
    # dl = L_o / 23 = 3.91 mm -> 128 nodes
    body_edges_per_side: int = setting(23,
                                       'dl = 90/23 = 3.91 mm ~ paper "dl ~ 4 mm, N = 128"',
                                       min=2, max=400, unit='-')
    # --- limbs ---
    # authors' code: rod radius ~2 mm
    limb_radius: float = setting(0.002,
                                 "authors' related code: limb rod radius ~2 mm (D = 4 mm in eq. 1, 3)",
                                 min=0.0005, max=0.01, unit='m')
    # E_0 [Pa] (paper)
    limb_young_relaxed: float = setting(3.0e6,
                                        "limb Young's modulus while the SMA is cold (relaxed); paper: E_0 = 3.0 MPa",
                                        min=100000.0, max=100000000.0, unit='Pa')
    # E_max [Pa] (paper; x2.68 while SMA is heated)
    limb_young_heated: float = setting(8.04e6,
                                       "limb Young's modulus while the SMA is heated (actuation phase); "
                                       'paper: E_max = 8.04 MPa',
                                       min=100000.0, max=100000000.0, unit='Pa')
    # EGaIn volume % of the interface layer
    egain_vol_pct: float = setting(10.0,
                                   'design variable, 0-50 % (paper); 10 % for the calibration runs',
                                   min=0.0, max=100.0, unit='%')
    # share of limb volume that is the LMEE layer
    interface_layer_fraction: float = setting(1.0 / 3.0,
                                              'assumption: limb = 3 equal layers (stretched, LMEE, unstretched '
                                              'silicone), paper Fig. 3a schematic',
                                              min=0.01, max=1.0, unit='-')
    silicone_density: float = setting(SILICONE_DENSITY,
                                      'Smooth-On silicone data sheets 1.07-1.08 g/cm^3',
                                      min=900.0, max=1300.0, unit='kg/m^3')
    egain_density: float = setting(EGAIN_DENSITY,
                                   'EGaIn 6.25 g/cm^3 (Dickey et al. 2008)',
                                   min=6000.0, max=6500.0, unit='kg/m^3')
    # --- body ---
    # [kg] four 3S 300 mAh LiPo (~28 g each) + PCB + foam + silicone
    body_mass: float = setting(0.150,
                               'estimate: four 3S 300 mAh LiPo (~28 g each, paper "Robot Electronics") + PCB, foam, '
                               'silicone',
                               min=0.02, max=1.0, unit='kg')
    # [m] z-extent: neutrally buoyant 150 g over (90^2-35^2) mm^2
    body_height: float = setting(0.022,
                                 'neutral buoyancy (paper: foam cancels battery weight): 150 g / 1000 kg/m^3 over '
                                 'the frame area 90^2 - 35^2 mm^2 = 22 mm (body EI, EA)',
                                 min=0.005, max=0.1, unit='m')
    # [Pa] effective; "four elastic rods with high stiffness"
    body_young_equivalent: float = setting(26.0e6,
                                           'assumption: "four elastic rods with high stiffness"; gives body EI ~ '
                                           '2.6e4 x limb EI so the body stays square',
                                           min=1000000.0, max=100000000000.0, unit='Pa')
    # [m] in-plane frame width (90 - 35) / 2 mm
    body_section_width: float = setting(0.0275,
                                        'frame width (L_o - L_i)/2 = 27.5 mm',
                                        min=0.002, max=0.1, unit='m')
    # [m] D of the body rods in eq. 1, 3 with body_fluid_section='rod' (the earlier model)
    body_rod_diameter: float = setting(0.004,
                                       'D of the body rods in drag eq. 1 and added mass eq. 3 with '
                                       "body_fluid_section='rod' only (the earlier model: the limbs' 4 mm, with "
                                       "which the authors' C_bn = 0.8 was calibrated); the default 'height' section "
                                       'uses H_f/H_a',
                                       min=0.001, max=0.1, unit='m')
    # --- fluid (paper, Hydrodynamic Characterization) ---
    # rho_f
    fluid_density: float = setting(WATER_DENSITY,
                                   'density of the water (drag eq. 1, added mass eq. 3); paper: rho_f = 1000',
                                   min=900.0, max=1100.0, unit='kg/m^3')
    # C_ln (a flat strip normal to the flow; calibrated on N-period replays; paper 1 for a rod)
    limb_drag_normal: float = setting(2.075,
                                      'joint calibration on N-period replays (frog-sweep calibrate-replays): 2.075; '
                                      'the limbs are flat strips (limb_fluid_width) and a flat plate normal to the '
                                      'flow has C_d ~ 2.0 (Hoerner, Fluid-Dynamic Drag, 1965, ch. 3: 1.98 for a 2D '
                                      'plate; 1.17 for a square one); paper: C_ln = 1 for a rod',
                                      min=0.0, max=5.0, unit='-')
    # C_lt
    limb_drag_tangent: float = setting(0.01,
                                       "tangential drag coefficient of the limbs (eq. 1); paper: C_lt = 0.01",
                                       min=0.0, max=1.0, unit='-')
    # C_bn (jointly calibrated with the body's height section; paper 0.8 with a 4 mm rod)
    body_drag_normal: float = setting(0.71,
                                      'joint calibration (frog-sweep calibrate): 0.71 with the body height'
                                      ' section (paper: 0.8 with a 4 mm rod, calibrated on the 10 % runs only)',
                                      min=0.0, max=5.0, unit='-')
    # C_bt
    body_drag_tangent: float = setting(0.008,
                                       'tangential drag coefficient of the body (eq. 1); '
                                       'paper: C_bt = 0.008 = C_bn / 100',
                                       min=0.0, max=1.0, unit='-')
    # C_a (theoretical value)
    added_mass_coefficient: float = setting(1.0,
                                            'added-mass coefficient (eq. 3); paper: C_a = 1 (theoretical)',
                                            min=0.0, max=3.0, unit='-')
    # --- actuation ---
    # hardware pulse [s] (DESIGN.md; paper 70 ms)
    pulse_duration: float = setting(0.080,
                                    'DESIGN.md hardware pulse 80 ms (paper characterisation 70 ms)',
                                    min=0.01, max=0.5, unit='s')
    # one primitive per 1.5 s (DESIGN.md)
    primitive_period: float = setting(1.5,
                                      'DESIGN.md: one primitive per 1.5 s',
                                      min=0.2, max=10.0, unit='s')
    # sense of the relaxed curl (see frog_model)
    limb_curl_direction: str = setting('forward',
                                       "'forward' = the relaxed curl turns a lateral limb toward the front, i.e. an "
                                       "aft-pointing limb away from the body axis; 'backward' the other way. Not "
                                       "shown by the paper; joint calibration (frog-sweep calibrate): 'forward' "
                                       "(per-period "
                                       "heading changes within 25 % of the robot's), 'backward' (the earlier choice,"
                                       ' from forward speed only) turns about half as much',
                                       choices=('forward', 'backward'), unit='-')
    # limb root direction: 0 lateral, -90 aft, +90 forward
    limb_root_angle_deg: float = setting(-90.0,
                                         'joint calibration (Fig. 2b gives no angle; frog-sweep calibrate): root '
                                         'direction of '
                                         'the rear limbs, turned from lateral (0) toward the rear: -90 = straight '
                                         'aft (the range bound). Was -75 from forward speed alone',
                                         min=-90.0, max=90.0, unit='deg')
    # --- fluid sections ---
    # 'rod': body drag/added mass with body_rod_diameter (the legacy 4 mm rod); 'height': the
    # body's own height, H_f at the front side to H_a at the rear side (Fig. 2b)
    body_fluid_section: str = setting('height',
                                      "'height': the body's sides are H_f (front) to H_a (rear) tall (Fig. 2b), so "
                                      "eq. 1 and 3 use that height as D; 'rod': the 4 mm body_rod_diameter",
                                      choices=('rod', 'height'), unit='-')
    # projected width of a limb strip normal to the swimming plane (drag eq. 1, added mass eq. 3)
    limb_fluid_width: float = setting(0.030,
                                      'joint calibration (frog-sweep calibrate): projected width of the flat limb '
                                      'strip normal '
                                      'to the plane (Fig. 3a): 30 mm, the upper bound (~ the body height); not given'
                                      ' by the paper (legacy: 4 mm = 2 r)',
                                      min=0.002, max=0.03, unit='m')
    # eq. 4 lumping of added mass: 'normal' (paper: full normal value at every node) or
    # 'direction_average' (half of it: a slender section has added mass only normal to itself)
    added_mass_lumping: str = setting('direction_average',
                                      "eq. 4 lumps added mass isotropically; 'direction_average' uses half the "
                                      'normal value (a slender section has added mass only normal to itself: exact '
                                      "for a translating square ring); 'normal' = paper",
                                      choices=('normal', 'direction_average'), unit='-')
    # front limbs' root direction relative to the rear limbs' (0: all four alike)
    front_root_angle_offset_deg: float = setting(32.0,
                                                 'joint calibration (frog-sweep calibrate): front limbs turned by '
                                                 'this much '
                                                 'toward the front relative to limb_root_angle_deg: 32 -> front '
                                                 'limbs 58 deg aft of lateral (Fig. 2b gives no angle for either '
                                                 'pair)',
                                                 min=-90.0, max=90.0, unit='deg')
    # --- linear damping lumped on the rigid body (core/body_damping.py) ---
    # X_u: surge
    surge_damping_linear: float = setting(0.05,
                                          'X_u of the linear damping lumped on the rigid body (Fossen D_L; radiation'
                                          ' damping, meniscus, limb recovery strokes; core/body_damping.py): 0.05, '
                                          'joint calibration on N-period replays of the nine hardware runs and all '
                                          'speeds (frog-sweep calibrate-replays, frog_sim/data/'
                                          'replay_calibration.json)',
                                          min=0.0, max=1.0, unit='N s/m')
    # Y_v: sway
    sway_damping_linear: float = setting(0.0,
                                         'Y_v of the same linear damping (sideways): 0, not calibrated (the side-'
                                         'slip targets are met without it; any Y_v > 0 lowers them)',
                                         min=0.0, max=1.0, unit='N s/m')
    # N_r: yaw
    yaw_damping_linear: float = setting(0.000375,
                                        'N_r of the same linear damping (yaw): 3.75e-4, joint calibration on '
                                        'N-period replays (frog-sweep calibrate-replays): a decay rate N_r / I = '
                                        "0.37 1/s (I = 1.0e-3 kg m^2 with the added mass), beside the limbs' "
                                        'quadratic drag and the waterline friction',
                                        min=0.0, max=0.05, unit='N m s/rad')

    # --- friction at the waterline (core/waterline_friction.py) ---
    # f: contact-line friction per unit length of the body's waterline
    waterline_friction: float = setting(0.003,
                                        "contact-angle hysteresis at the waterline, per unit length of the body's "
                                        'waterline: a rate-independent force 2 f L_o against the swimming and a '
                                        'torque f L_o^2 against the turn (core/waterline_friction.py), what stops a '
                                        'turn within the period: 0.003, joint calibration on N-period replays of the '
                                        'nine hardware runs (frog-sweep calibrate-replays; about 2 deg of contact-'
                                        'angle hysteresis at 72 mN/m)',
                                        min=0.0, max=0.05, unit='N/m')

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first value outside its range or choices."""
        reason = check(self)
        if reason:
            raise ValueError(reason)

    # ---- derived quantities -------------------------------------------------
    @property
    def edge_length(self) -> float:
        """Rest length dl of every edge [m] (body side / edges per side)."""
        return self.body_side_length / int(self.body_edges_per_side)

    @property
    def limb_edges(self) -> int:
        """Number of edges per limb (limb length rounded to whole edges)."""
        return max(2, int(round(self.limb_length / self.edge_length)))

    @property
    def limb_area(self) -> float:
        """Limb cross-section area pi r^2 [m^2]."""
        return np.pi * self.limb_radius ** 2

    @property
    def limb_second_moment(self) -> float:
        """Limb area moment pi r^4 / 4 [m^4]."""
        return np.pi * self.limb_radius ** 4 / 4.0

    @property
    def limb_density(self) -> float:
        """Limb density [kg/m^3]: silicone with EGaIn in the interface layer (rule of mixtures)."""
        phi = self.egain_vol_pct / 100.0 * self.interface_layer_fraction
        return (1.0 - phi) * self.silicone_density + phi * self.egain_density

    @property
    def body_linear_density(self) -> float:
        """Body mass per unit centre-line length [kg/m]."""
        return self.body_mass / (4.0 * self.body_side_length)

    @property
    def body_bending_stiffness(self) -> float:
        """Body EI [N m^2] with I = h w^3 / 12 of the frame section."""
        return self.body_young_equivalent * self.body_height * self.body_section_width ** 3 / 12.0

    @property
    def body_stretching_stiffness(self) -> float:
        """Body EA [N]."""
        return self.body_young_equivalent * self.body_height * self.body_section_width


#: Human-readable provenance of every field of :class:`FrogParameters` (name -> (unit, source)).
PARAMETER_SOURCES: dict[str, tuple[str, str]] = {f.name: (f.metadata['unit'], f.metadata['description'])
                                                 for f in fields(FrogParameters)}


def _field(name: str):
    for f in fields(FrogParameters):
        if f.name == name:
            return f
    known = [f.name for f in fields(FrogParameters)]
    import difflib
    close = difflib.get_close_matches(name, known, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ''
    raise KeyError(f'{name!r} is not a FrogParameters field{hint}')


def parameter_range(name: str) -> tuple[float, float] | None:
    """Physically plausible ``(lo, hi)`` of a numeric field (``None`` for a choice field).

    Raises
    ------
    KeyError
        If ``name`` is not a field (the message suggests the closest name).

    Examples
    --------
    >>> parameter_range('body_mass')
    (0.02, 1.0)
    """
    md = _field(name).metadata
    return None if md['min'] is None else (md['min'], md['max'])


def parameter_unit(name: str) -> str:
    """SI unit of a field (``'-'`` for dimensionless)."""
    return _field(name).metadata['unit']


def parameter_specs() -> list[dict]:
    """One dict per field: ``name, default, type, unit, range`` (or ``choices``), ``source``.

    This is the single table from which ROS parameter descriptors (``model.*``) and the
    validation are built.
    """
    out = []
    for f in fields(FrogParameters):
        spec = {'name': f.name, 'default': getattr(DEFAULT_PARAMETERS, f.name), 'type': f.type,
                'unit': f.metadata['unit'], 'source': PARAMETER_SOURCES[f.name][1]}
        if f.metadata['min'] is not None:
            spec['range'] = (f.metadata['min'], f.metadata['max'])
        if f.metadata['choices'] is not None:
            spec['choices'] = f.metadata['choices']
        out.append(spec)
    return out


def parameter_table(params: FrogParameters | None = None) -> list[tuple[str, object, str, str]]:
    """Rows ``(name, value, unit, source)`` for every parameter, plus derived values.

    Parameters
    ----------
    params : FrogParameters, optional
        Parameter set (default: :class:`FrogParameters` defaults).

    Returns
    -------
    list of tuple
        One row per field, then derived rows (dl, limb density, EI, EA, ...).
    """
    p = params or FrogParameters()
    rows = [(name, value, *PARAMETER_SOURCES[name]) for name, value in p.as_dict().items()]
    rows += [
        ('edge_length (derived)', p.edge_length, 'm', 'L_o / body_edges_per_side'),
        ('limb_edges (derived)', p.limb_edges, '-', 'round(L_i / dl)'),
        ('limb_density (derived)', p.limb_density, 'kg/m^3', 'rule of mixtures'),
        ('limb_EI_relaxed (derived)', p.limb_young_relaxed * p.limb_second_moment, 'N m^2',
         'E_0 pi r^4/4'),
        ('limb_EA_relaxed (derived)', p.limb_young_relaxed * p.limb_area, 'N', 'E_0 pi r^2'),
        ('body_EI (derived)', p.body_bending_stiffness, 'N m^2', 'E_b h w^3/12'),
        ('body_EA (derived)', p.body_stretching_stiffness, 'N', 'E_b h w'),
    ]
    return rows


DEFAULT_PARAMETERS = FrogParameters()
DEFAULT_PARAMETERS.validate()

__all__ = ['FrogParameters', 'PARAMETER_SOURCES', 'parameter_table', 'DEFAULT_PARAMETERS',
           'parameter_range', 'parameter_unit', 'parameter_specs',
           'WATER_DENSITY', 'EGAIN_DENSITY', 'SILICONE_DENSITY']
