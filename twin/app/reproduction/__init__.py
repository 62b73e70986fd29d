"""The thesis reproduction: which of the thesis's numbers can be trusted (scripts/reproduce_thesis.py).

* ``claims`` — the ``Claim`` record (where, printed value, recomputation, check, hypotheses) and ``evaluate``,
  the one rule that turns a claim into an ``Entry`` with a computed verdict;
* ``models`` — what the numbers are recomputed from (``Model(params)``);
* ``numbers`` — the claims of chapters 3–5 and appendix A; ``closed_loop`` (with ``scenarios``) — the
  figures and statements of chapters 4, 5 and 7, each declaring its runs of ``twin.rigs.sim.run_closed_loop``;
* ``markdown``, ``figures`` — rendering only; ``report`` — evaluate everything and write it.
"""
