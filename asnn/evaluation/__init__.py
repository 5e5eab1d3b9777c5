"""Measuring the detectors: scoring, evaluation runs, figures and benchmarks.

Nothing here is imported by the model. The submodules are imported explicitly (``figures``
loads matplotlib):

:mod:`~asnn.evaluation.labels`
    Clip labels (``labels.json``), checked where they are read.
:mod:`~asnn.evaluation.scoring`
    Outcomes of per-frame results against clip labels (SPEC.md section 5).
:mod:`~asnn.evaluation.runs`
    Detector specs (``asnn``, ``asnn:PRESET``, ``lgmd1``, ``lgmd2``) and running them over frames.
:mod:`~asnn.evaluation.clips`
    Every detector over a folder of labelled clips (``asnn eval CLIPS_DIR``).
:mod:`~asnn.evaluation.suite`
    Every detector over the labelled suite of generated scenes (``asnn eval --synthetic``).
:mod:`~asnn.evaluation.paper`
    The paper's synthetic experiments, Figs. 3 and 6-9 (``asnn eval --paper``).
:mod:`~asnn.evaluation.ttc`
    The targets' time to contact on approaches of known contact time (``asnn eval --ttc``).
:mod:`~asnn.evaluation.bench`
    Per-frame timing of every model and preset (``asnn bench``).
:mod:`~asnn.evaluation.figures`, :mod:`~asnn.evaluation.progress`
    Plots, and the progress bar of the long-running commands.
"""
