"""Networks of icmapper in plain PyTorch: image backbone, BEV view transformer with temporal memory,
map decoder, query propagation (U_MLP), association, spatial fusion, Hungarian matcher and losses.

Model code holds no I/O: no paths, no dataset knowledge, no global state.
"""
