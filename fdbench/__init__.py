"""fdbench: a benchmark of trajectory-tracking methods for forward dynamic simulation.

A 1-DOF forearm must follow a prescribed elbow rotation; fdbench compares PD control with
computed feedforward against optimised torque histories (ANN, cubic spline, parametric
function) by RMSE of rotation, RMSE of torque and runtime.
"""

__version__ = "0.1.0"
