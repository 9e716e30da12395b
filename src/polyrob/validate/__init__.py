"""Validation of a controller beyond its μ certificate.

Each stage takes the previous stage's object:

* :mod:`~polyrob.validate.monte_carlo` - S, T, KS and step responses of the
  nominal and sampled plants of the uncertain plant, with the weight shapes;
* :mod:`~polyrob.validate.simulate` - the robot's true nonlinear dynamics in
  closed loop with the continuous controller or its sampled-and-held
  discretisation, with per-joint figures and the domain check (whether the
  certificate applies to the trajectory at all);
* :mod:`~polyrob.validate.discretize` - Tustin (pre-warped) / ZOH
  discretisation, stability and μ of the discretised loop, lowest sample rate;
* :mod:`~polyrob.validate.quantize` - second-order sections per controller
  entry, fixed-point coefficient quantisation, shortest word length;
* :mod:`~polyrob.validate.export_c` - C (``controller.h``/``controller.c``)
  and JSON of the discrete controller.
"""
