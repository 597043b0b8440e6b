"""The paper's study in the simulated wave basin, upstream to downstream:

- :mod:`.paper`: the paper's own numbers and words (Tables I-IV, the statements it makes);
- :mod:`.claims`: the paper's claims as typed records (quantities, comparison, explanation);
- :mod:`.maps`: Table IV's four maps and every map metric (C2C, cells, the bathymetric surface
  error, accuracy / completeness / F-score), on the wave conditions and the mapping scenarios;
- :mod:`.pipeline`: one seed end to end (simulate, characterize, calibrate, localize, map,
  evaluate) -> plain numbers and the claims' verdicts;
- :mod:`.stats`: aggregation over seeds (Student-t intervals, claim fractions);
- :mod:`.tables`: the paper's tables with the simulated values next to the paper's;
- :mod:`.report`: the study's figures and HTML page, drawn by the generic :mod:`undertow.report`;
- :mod:`.batch`: seeds as independent Dask tasks (any function of a seed; no study knowledge);
- :mod:`.runner`: the whole study (`undertow reproduce` / `demo`): seeds, files, report.
"""
