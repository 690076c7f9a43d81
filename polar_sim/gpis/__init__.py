"""polar_sim.gpis"""
