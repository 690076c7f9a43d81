"""polar_sim.tracking"""
