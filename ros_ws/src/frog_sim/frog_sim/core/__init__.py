"""Pure-Python core of frog_sim: no rclpy imports, unit-tested without ROS.

Modules (one concern each):

* ``model_parameters`` - every physical parameter with its source (``parameter_table``)
* ``rod_network``      - nodes, edges, bending triples (joint nodes allowed), builders
* ``elastic_energy``   - E_s, E_b with analytic gradients/Hessians (numba kernels)
* ``fluid``            - quadratic drag eq. 1-2 (+ Jacobian), added mass eq. 3-4
* ``linear_algebra``   - Jacobian pattern, static sparse LU plan (numba)
* ``integrator``       - backward Euler + Newton eq. 6-8, step halving, ConvergenceError
* ``actuation``        - eq. 9 fits of the measured limb profiles (cached), numba evaluation
* ``schedules``        - gaits and the nine primitives as limb firing times
* ``frog_model``       - the square robot of Fig. 2 as a rod network
* ``rigid_body``       - eq. 10-13 (COM, heading, velocities, yaw rate and inverse)
* ``simulation``       - public API: ``FrogSimulation``, ``Trajectory``
* ``rollouts``         - batched rollouts from an estimated state for the planner (``Rollouts``)
* ``reference_numpy``  - plain numpy/scipy version of the step (benchmark baseline)
"""
