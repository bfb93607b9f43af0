"""Closed-loop demo: the node graph over DDS (`demo`), its processes and its report."""
