"""Analyses beyond the paper, built on a ranking: ISO/TS 15066 force limits (``iso15066``; its
body-region table: ``body_regions``), exposed points of the object (``exposed_points``),
inertia uncertainty (``uncertainty``), grasp quality trade-off (``multi_objective``),
null-space posture (``redundancy``), joint effort (``effort``), and ``safety_report``, which
runs the selected ones in one call."""
