"""The pixel phase-field equation: the physics the network is trained on, the exact pixel solve,
and the certificate and correction of the verified step, in one place.

- :mod:`~ifenn.pixel_equation.definition`: the equation's coefficients, stencil and padding, read
  by both backends (:class:`PixelOperator`);
- :mod:`~ifenn.pixel_equation.numpy_backend`: numpy and the compiled kernel (the CPU's step, the
  exact solve, the smoothing, the correction boxes);
- :mod:`~ifenn.pixel_equation.torch_backend`: torch (the training loss, the GPU's step), with its
  multigrid in :mod:`~ifenn.pixel_equation.torch_multigrid`.

The two backends keep the same names for the same things (``bounding_box``, ``gaussian_smoothing``,
a pixel equation's ``residual`` and ``solve_box``); import them from the backend you run on.
"""

from ifenn.pixel_equation.definition import EQUATION_PADDINGS, PixelOperator

__all__ = ["EQUATION_PADDINGS", "PixelOperator"]
