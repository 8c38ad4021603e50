"""mjx-protamer: self-touch exploration in MuJoCo-MJX guided by human (voice) feedback.

Importing the package is cheap and imports no JAX: the host-side pieces (feedback events, queue,
audio front end) use it without pulling in the learner.
"""

__version__ = "0.1.0"
