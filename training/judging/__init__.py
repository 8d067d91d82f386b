"""Judging controllers, apart from training them: ``proteo eval`` and ``proteo eval --benchmark``.

- :mod:`~training.judging.protocol`: what is judged, on which worlds (``configs/benchmark/<version>.yaml``);
- :mod:`~training.judging.episodes`: ``proteo eval``'s episode jobs (the batched evaluator stays in
  :mod:`training.evaluator`, because the trainers use it too);
- :mod:`~training.judging.report`: the result records of ``proteo eval`` (:mod:`~training.judging.evaluate`
  runs it); :mod:`~training.judging.judge`: ``proteo eval --benchmark``;
- :mod:`~training.judging.statistics`: the intervals and the paired comparisons;
- :mod:`~training.judging.results`: the results page;
- :mod:`~training.judging.pages`: the one way to publish a table into a markdown file.
"""
