"""The engines that draw the modes' frames, one module each (:mod:`.base` describes the layer
and holds what the OpenCL engines share): :mod:`.projection`, :mod:`.gather`, :mod:`.runs`,
:mod:`.blend` and the detail step :mod:`.detail`. Each kernel file is named after its engine
(``kernels/projection.cl``, ``kernels/gather.cl``, ``kernels/runs.cl``, ...).
"""
