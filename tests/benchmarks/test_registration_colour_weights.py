"""Short version of ``benchmarks.registration_colour_weights``: the colour blocks weigh 0 on a
grey image and more on a colourful one than on the same scene 30x darker."""

import cv2
import numpy as np

from benchmarks.registration_colour_weights import image_weights
from tests.vision.features_utils import textured_rgb


def test_weights_are_zero_on_grey_and_fall_in_the_dark():
    rgb = textured_rgb(0)
    grey = cv2.cvtColor(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
    w, zero, _, n = image_weights(grey, "sift")
    assert n > 50 and w == 0.0 and zero == 1.0
    bright = image_weights(rgb, "sift")
    rng = np.random.default_rng(0)
    dark = np.clip(rng.poisson(rgb / 30.0) + rng.normal(0, 0.5, rgb.shape), 0, 255)
    dim = image_weights(dark.astype(np.uint8), "sift")
    assert bright[0] > 0.3 and bright[2] > 10 * dim[2]
    assert dim[3] == 0 or dim[0] < bright[0]
