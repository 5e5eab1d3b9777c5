"""Reading and writing pictures: frame sources in (video files, devices, streams, generated
scenes, ROS 2 bags: :mod:`asnn.io.sources`), annotated videos, plots and Foxglove files out;
files replaced whole under a folder lock (:mod:`asnn.io.files`: the labels files).

The model never imports this package; the command line and the evaluation do.
"""
