"""Post-processing of result files: curves, derived fields, summaries (``parsolve post``)."""
