"""Symmetry-guided point cloud completion (paper section III-C).

:mod:`~volec.completion.preprocess` (normalize, resample, outlier removal),
:mod:`~volec.completion.model` (SymmCompletion: LSTNet + SGFormer in plain torch),
:mod:`~volec.completion.data` (partial views of procedural shapes for training),
:mod:`~volec.completion.train` (training, checkpoints), :mod:`~volec.completion.complete`
(completing a metric cloud), :mod:`~volec.completion.mirror` (the mirror-symmetry baseline)
and :mod:`~volec.completion.rotation` (rotational symmetry about the support normal).
"""
