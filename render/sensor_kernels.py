"""Camera-sensor effects as three launches over a whole batch of 8-bit images, in the order a camera applies them:
colour (white balance, hue and saturation, contrast, brightness), a Gaussian defocus blur (rows, then columns) and
read + shot noise with the final quantization. Each image has its own values; the arithmetic follows OpenCV's
(``cv2.cvtColor`` float HSV, ``cv2.GaussianBlur`` with ``ksize (0, 0)``: kernel side ``round(8 sigma + 1) | 1``,
``BORDER_REFLECT_101``), so the host reference (:func:`warpworm.render.sensor.apply_sensor_opencv`) agrees to
float rounding. Noise comes from Warp's counter-based generator keyed by each image's seed and row.
"""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})

FLT_EPSILON = wp.constant(1.1920929e-07)


@wp.func
def rgb_to_hsv(c: wp.vec3) -> wp.vec3:
    """OpenCV's float RGB -> HSV: H in [0, 360) [deg], S and V in [0, 1]."""
    r = c[0]
    g = c[1]
    b = c[2]
    v = wp.max(wp.max(r, g), b)
    vmin = wp.min(wp.min(r, g), b)
    diff = v - vmin
    s = diff / (wp.abs(v) + FLT_EPSILON)
    diff = 60.0 / (diff + FLT_EPSILON)
    h = float(0.0)
    if v == r:
        h = (g - b) * diff
    elif v == g:
        h = (b - r) * diff + 120.0
    else:
        h = (r - g) * diff + 240.0
    if h < 0.0:
        h += 360.0
    return wp.vec3(h, s, v)


@wp.func
def hsv_to_rgb(c: wp.vec3) -> wp.vec3:
    """OpenCV's float HSV -> RGB (H in degrees)."""
    h = c[0]
    s = c[1]
    v = c[2]
    out = wp.vec3(v, v, v)
    if s != 0.0:
        h = h * (1.0 / 60.0)
        while h < 0.0:
            h += 6.0
        while h >= 6.0:
            h -= 6.0
        sector = int(wp.floor(h))
        h -= float(sector)
        if sector < 0 or sector >= 6:
            sector = 0
            h = 0.0
        t0 = v
        t1 = v * (1.0 - s)
        t2 = v * (1.0 - s * h)
        t3 = v * (1.0 - s * (1.0 - h))
        # OpenCV's sector table {1,3,0}, {1,0,2}, {3,0,1}, {0,2,1}, {0,1,3}, {2,1,0} picks (b, g, r) from (t0..t3)
        if sector == 0:
            out = wp.vec3(t0, t3, t1)
        elif sector == 1:
            out = wp.vec3(t2, t0, t1)
        elif sector == 2:
            out = wp.vec3(t1, t0, t3)
        elif sector == 3:
            out = wp.vec3(t1, t2, t0)
        elif sector == 4:
            out = wp.vec3(t3, t1, t0)
        else:
            out = wp.vec3(t0, t1, t2)
    return out


@wp.kernel
def sensor_colour(
    rgb: wp.array2d(dtype=wp.vec3ub),
    white_balance: wp.array(dtype=wp.vec3),
    hue_sat_con_bri: wp.array(dtype=wp.vec4),
    width: int,
    # Data out:
    out: wp.array2d(dtype=wp.vec3),
):
    """Colour effects of row y of image ``img`` (launched (N, H): a CPU thread's set-up paid once per row): 8-bit
    display RGB -> [0, 1], per-channel gains (clipped to [0, 1] when not all 1), hue shift [deg] and saturation gain
    through HSV (skipped when neutral), then ``(c - 0.5) contrast + 0.5 + brightness`` (not clipped: blur and noise
    come first)."""
    img, y = wp.tid()
    wb = white_balance[img]
    hscb = hue_sat_con_bri[img]
    gains = wb[0] != 1.0 or wb[1] != 1.0 or wb[2] != 1.0
    hsv_on = hscb[0] != 0.0 or hscb[1] != 1.0
    for pix in range(y * width, y * width + width):
        p = rgb[img, pix]
        c = wp.vec3(float(p[0]), float(p[1]), float(p[2])) * (1.0 / 255.0)
        if gains:
            c = wp.cw_mul(c, wb)
            c = wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))
        if hsv_on:
            hsv = rgb_to_hsv(c)
            h = wp.mod(hsv[0] + hscb[0], 360.0)
            if h < 0.0:
                h += 360.0
            c = hsv_to_rgb(wp.vec3(h, wp.clamp(hsv[1] * hscb[1], 0.0, 1.0), hsv[2]))
        out[img, pix] = (c - wp.vec3(0.5)) * hscb[2] + wp.vec3(0.5 + hscb[3])


@wp.func
def reflect101(i: int, n: int) -> int:
    """OpenCV's BORDER_REFLECT_101 index (gfedcb|abcdefgh|gfedcba) for a tap within one image side of the edge."""
    j = i
    if j < 0:
        j = -j
    if j >= n:
        j = 2 * n - 2 - j
    return wp.clamp(j, 0, n - 1)


@wp.func
def blur_taps(src: wp.array2d(dtype=wp.vec3), img: int, base: int, pos: int, n: int, stride: int,
              weights: wp.array2d(dtype=float), radius: int) -> wp.vec3:
    """Symmetric 1-D Gaussian at ``pos`` of a line of ``n`` pixels (``base + i * stride``): the centre tap plus
    each pair of mirrored taps, as OpenCV's symmetric row and column filters sum them. ``weights`` (N, 2 R + 1):
    every image's kernel centred at column R (the batch's widest), ``radius`` <= R this image's."""
    c = weights.shape[1] / 2
    acc = src[img, base + pos * stride] * weights[img, c]
    if pos >= radius and pos + radius < n:  # away from the border: no reflection (the same sums)
        for d in range(1, radius + 1):
            pair = src[img, base + (pos - d) * stride] + src[img, base + (pos + d) * stride]
            acc = acc + pair * weights[img, c + d]
    else:
        for d in range(1, radius + 1):
            a = src[img, base + reflect101(pos - d, n) * stride]
            b = src[img, base + reflect101(pos + d, n) * stride]
            acc = acc + (a + b) * weights[img, c + d]
    return acc


@wp.kernel
def sensor_blur_rows(
    src: wp.array2d(dtype=wp.vec3),
    weights: wp.array2d(dtype=float),
    radius: wp.array(dtype=wp.int32),
    width: int,
    # Data out:
    dst: wp.array2d(dtype=wp.vec3),
):
    """The blur along row y (launched (N, H)); ``weights`` (N, 2 R + 1) each image's kernel centred at column R,
    ``radius`` (N,) its half side (0: copy)."""
    img, y = wp.tid()
    r = radius[img]
    for x in range(width):
        if r == 0:
            dst[img, y * width + x] = src[img, y * width + x]
        else:
            dst[img, y * width + x] = blur_taps(src, img, y * width, x, width, 1, weights, r)


NORMAL_TABLE_BITS = 16
"""Each standard normal draw is the quantile of one of 2^16 equally likely levels (:func:`normal_table`)."""


@wp.func
def normal_pair(state: wp.uint32, table: wp.array(dtype=float)):
    """Two independent standard normal draws from one 32-bit output of the generator at ``state``: its two 16-bit
    halves index ``table``, the normal quantiles at (i + 1/2) / 2^16 (inverse-transform sampling: no logarithm,
    no rejection; tails to 4.3 sigma), and the advanced state."""
    bits = wp.randu(state)
    lo = int(bits & wp.uint32(65535))
    hi = int(bits >> wp.uint32(16))
    return wp.vec2(table[lo], table[hi]), state


@wp.kernel
def sensor_blur_cols_noise(
    src: wp.array2d(dtype=wp.vec3),
    weights: wp.array2d(dtype=float),
    radius: wp.array(dtype=wp.int32),
    noise: wp.array(dtype=wp.vec2),
    seed: wp.array(dtype=wp.int32),
    normal_table: wp.array(dtype=float),
    width: int,
    height: int,
    # Data out:
    rgb: wp.array2d(dtype=wp.vec3ub),
):
    """The blur along columns, then noise of std ``noise[img][0] + noise[img][1] sqrt(clip(c, 0, 1))`` (read and
    shot, fractions of full scale; a normal draw per channel from the row's stream, keyed by ``seed[img]`` and the
    row: three 32-bit outputs, six :func:`normal_pair` draws, per two pixels; ``normal_table`` (2^16,) the normal
    quantiles) and the 8-bit quantization ``floor(clip(c, 0, 1) 255 + 0.5)`` (launched
    (N, H): a row per thread, on every device, so the draws do not depend on it)."""
    img, y = wp.tid()
    r = radius[img]
    ns = noise[img]
    noisy = ns[0] > 0.0 or ns[1] > 0.0
    state = wp.rand_init(seed[img], y)
    z = wp.vec3(0.0)
    z_next = wp.vec3(0.0)
    for x in range(width):
        pix = y * width + x
        c = src[img, pix]
        if r != 0:
            c = blur_taps(src, img, x, y, height, width, weights, r)
        if noisy:
            if x % 2 == 0:  # this pixel's and the next one's six draws
                p0, state = normal_pair(state, normal_table)
                p1, state = normal_pair(state, normal_table)
                p2, state = normal_pair(state, normal_table)
                z = wp.vec3(p0[0], p0[1], p1[0])
                z_next = wp.vec3(p1[1], p2[0], p2[1])
            else:
                z = z_next
            std = wp.vec3(ns[0])
            if ns[1] > 0.0:
                std = std + ns[1] * wp.vec3(wp.sqrt(wp.clamp(c[0], 0.0, 1.0)), wp.sqrt(wp.clamp(c[1], 0.0, 1.0)),
                                            wp.sqrt(wp.clamp(c[2], 0.0, 1.0)))
            c = c + wp.cw_mul(z, std)
        rgb[img, pix] = wp.vec3ub(wp.uint8(int(wp.clamp(c[0], 0.0, 1.0) * 255.0 + 0.5)),
                                  wp.uint8(int(wp.clamp(c[1], 0.0, 1.0) * 255.0 + 0.5)),
                                  wp.uint8(int(wp.clamp(c[2], 0.0, 1.0) * 255.0 + 0.5)))
