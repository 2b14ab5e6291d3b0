"""Round trips of the shared host transforms against an independent construction."""

import numpy as np

from warpworm import transforms as tf


def _random_rotations(n, rng):
    # QR of Gaussian matrices gives Haar-distributed rotations, independent of our quaternion code.
    Q, Rr = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    Q = Q * np.sign(np.diagonal(Rr, axis1=1, axis2=2))[:, None, :]
    Q[np.linalg.det(Q) < 0, :, 0] *= -1
    return Q


def test_matrix_quaternion_round_trip():
    rng = np.random.default_rng(0)
    R = _random_rotations(500, rng)
    q = tf.matrix_to_quat_wxyz(R)
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0)
    assert np.all(q[:, 0] >= 0)
    assert np.allclose(tf.quat_wxyz_to_matrix(q), R, atol=1e-12)


def test_axis_angle_matches_quaternion():
    rng = np.random.default_rng(1)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(-np.pi, np.pi)
        q = np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])
        assert np.allclose(tf.axis_angle_to_matrix(axis, angle), tf.quat_wxyz_to_matrix(q), atol=1e-12)


def test_pose_inverse():
    rng = np.random.default_rng(2)
    R = _random_rotations(10, rng)
    t = rng.normal(size=(10, 3))
    T = tf.pose_matrix(R, t)
    assert np.allclose(T @ tf.invert_pose(T), np.eye(4), atol=1e-12)


def test_quaternion_order_matches_warp():
    """Our (w, x, y, z) -> Warp's (x, y, z, w) conversion gives the rotation Warp itself builds from it."""
    import warp as wp

    rng = np.random.default_rng(3)
    R = _random_rotations(10, rng)
    q = tf.matrix_to_quat_wxyz(R)
    for Ri, qi in zip(R, tf.quat_wxyz_to_xyzw(q)):
        Rw = np.array(wp.quat_to_matrix(wp.quat(*qi.astype(np.float32))), dtype=np.float64).reshape(3, 3)
        assert np.allclose(Rw, Ri, atol=1e-6)
    assert np.allclose(tf.quat_xyzw_to_wxyz(tf.quat_wxyz_to_xyzw(q)), q)
