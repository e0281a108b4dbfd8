"""From depth-camera captures to simulation-ready terrain meshes (Tong 2018, sections 3.1-3.2).

Not built yet: see issue 7.
"""
