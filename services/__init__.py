"""spacemap services: simulator, robot agent, edge server, launcher and evaluator."""

import os

# Several services share a few cores; threaded BLAS only adds contention (field notes: numpy
# post-processing of a frame 72 ms → 21 ms). Must be set before numpy is first imported.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
