"""Reading and writing pictures: video files in, annotated videos and plots out.

The model never imports this package; the command line and the evaluation do.
"""
