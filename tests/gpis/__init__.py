"""Tests of polar_sim.gpis."""
