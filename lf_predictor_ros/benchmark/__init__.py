"""Scenario suite: the adaptive predictor against the classical wave filters."""
