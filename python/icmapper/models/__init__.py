"""Networks of icmapper in plain PyTorch: image backbone, BEV view transformer with temporal memory,
map decoder, query propagation (U_MLP), association, spatial fusion, Hungarian matcher and losses;
``config.ModelConfig`` (their settings), ``network.ICMapperNet`` (the whole network) and
``network.load_network`` (a checkpoint for inference).

Model code holds no paths and no dataset knowledge; the only I/O is the checkpoint file format
(``checkpoint.py``) and ``network.load_network``.
"""
