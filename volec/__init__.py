"""volec: food volume in millilitres from a phone capture.

Stages (one module each): capture I/O -> sfm -> segment -> dense -> masking -> completion ->
meshing -> volume. The synthetic FoodKit benchmark generator lives in :mod:`volec.synth`.
"""

__version__ = "0.1.0"
