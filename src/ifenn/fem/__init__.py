"""The finite-element core: structured Q1 meshes with slit notches (``mesh``), the model's UFL forms
(``elasticity``; the phase-field model is ``ifenn.models``), the fracture problem and its solvers (``problem``), the FEM phase-field step
(``phase_field``), load control (``loading``) and the staggered loop with its outputs (``solver``).
"""
