"""
umbrella_sim: real-time flexible multibody simulation of an umbrella-frame antenna.

The physics core (params, model, rigid, solver, outputs) imports no ROS package.
"""
__version__ = "0.1.0"
