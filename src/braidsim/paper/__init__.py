"""The paper's reported values as data, and the reproduction report of ``braidsim paper``.

- :mod:`braidsim.paper.values`: ``paper_values.toml`` (every number of sections 3.1-3.5) as
  frozen objects;
- :mod:`braidsim.paper.compute`: our value of each item over its run and window;
- :mod:`braidsim.paper.findings`: evidence behind our readings of the paper (docs/model.md)
  and the cause of each deviation;
- :mod:`braidsim.paper.figures`: Figures 3-22, the added figures, Table 1;
- :mod:`braidsim.paper.report`: the whole command (:func:`reproduce`).
"""

from braidsim.paper.values import PaperItem, PaperValues, RunSpec, load_paper_values

__all__ = ["PaperItem", "PaperValues", "RunSpec", "load_paper_values"]
