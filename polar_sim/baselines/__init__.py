"""polar_sim.baselines"""
