"""2D discrete-elastic-rods simulator of the frog-inspired swimming soft robot (seed 000): rod
network, fluid drag and added mass, SMA limb actuation, design sweeps, motion-primitive library,
and the simulator node (digital twin).
"""
