"""vision: colour-histogram object recognition and stereo localization (pure OpenCV + numpy, no zenoh).

Implements "Object Recognition and Localization" of Yoshida et al. (001_771c0ce3779b0683.txt):
histogram.py (Hue-Saturation models), backproject.py, camshift.py (CamShift, re-detection, tracking),
stereo.py (centroid triangulation, dense stereo), localize.py (one call: stereo pair -> world positions),
cli.py (``perception learn``), synthetic.py (ray-cast test images), demo.py. See vision/README.md.
"""
