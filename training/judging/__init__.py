"""Judging controllers, apart from training them: ``proteo eval`` and ``proteo eval --benchmark``.

protocol -> episodes -> one result record and file -> statistics -> pages:

- :mod:`~training.judging.protocol`: what is judged, on which worlds (``configs/benchmark/<version>.yaml``);
- :mod:`~training.judging.episodes`: running the planned episodes (:class:`training.machinery.evaluator.Episode`,
  the batched evaluator, which stays in :mod:`training.machinery.evaluator` because the trainers use it too);
- :mod:`~training.judging.report`: the one result record (:class:`~training.judging.report.Result`:
  a policy, or a recipe's training seeds, on a task and split), its table columns and figure;
- :mod:`~training.judging.record`: the one file format of every judgement (``results.json``,
  ``benchmark.json``) and its table page, read back in any version;
  :mod:`~training.judging.evaluate` runs ``proteo eval``, :mod:`~training.judging.judge`
  ``proteo eval --benchmark``, both through one :class:`~training.judging.episodes.Plan`;
- :mod:`~training.judging.statistics`: the intervals and the paired comparisons;
- :mod:`~training.judging.results`: the results page, with the learning curves of
  :mod:`~training.judging.plots`;
- :mod:`~training.judging.pages`: the one way to publish a table into a markdown file.

A policy from outside (an entrant) is loaded by :mod:`training.machinery.entrants`, beside the
checkpoints' loaders, since the batched evaluator builds it.
"""
