"""The physics-informed network: the PICNN and its pixel equation (``picnn``), the symmetric-kernel
evaluation and its compiled kernel (``orbit``, ``orbit_kernel``), training and its data
(``training``, ``training_data``).
"""
