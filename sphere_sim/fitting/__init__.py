"""Fitting the model to a device: the calibration to the paper's figures, identification from
recorded kicks (observations, the misfit's scan) and the throughput of these kick workloads.

Stands above the kicks and the studies, whose kicks and whole runs it fits with.
"""
