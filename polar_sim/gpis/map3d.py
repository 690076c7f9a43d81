"""placeholder"""
class GPISMap3D:
    pass
