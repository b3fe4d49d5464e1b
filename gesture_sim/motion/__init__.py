"""Motion capture readers, retargeting, segmentation, kinematic parameters, the motion library."""
