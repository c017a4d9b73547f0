"""The command line (``main``: ``grasp-safety``), its scenario files (``scenario``), text and
JSON reports (``report``) and plots (``plotting``)."""
