"""The child interpreter of a capped peer run (:func:`undertow.study.peers.run_capped`):

    python -m undertow.study.peer_worker JOB.pkl RESULT.pkl

reads (estimator, log, options) from JOB.pkl, runs the estimator and writes
(ok, trajectory or one-line error, CPU seconds) to RESULT.pkl, the CPU time being this
process's ``time.process_time()`` around the call. The parent kills it at the cap.
"""

from __future__ import annotations

import pickle
import sys
import time
import warnings


def main(job: str, result: str) -> int:
    from .._util.dask import describe_exception
    from .peers import call_estimator

    with open(job, "rb") as f:
        estimator, log, options = pickle.load(f)
    start = time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            outcome = (True, call_estimator(estimator, log, options))
    except Exception as exc:  # reported to the parent as one line
        outcome = (False, describe_exception(exc))
    cpu_s = time.process_time() - start
    with open(result, "wb") as f:
        pickle.dump((*outcome, cpu_s), f)
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
