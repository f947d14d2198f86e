/*
 * fusiond.estimator._kernels: the error-state EKF's fixed-size linear algebra, compiled.
 *
 * Why C and not numba. At the 9-15 dimensional states fusiond runs, a numpy call
 * costs more in dispatch than in arithmetic, so the propagation P' = F P F^T + Q and the masked
 * Kalman update were ~20 us of Python and numpy calls per step. numba compiles the same loops,
 * but importing it and loading its cache costs 0.4 s + ~0.85 s per process (measured on this
 * project's 2-core machine), more than a whole `fusiond replay` of the Jackal bag takes. This
 * module imports in well under a millisecond and needs nothing but the C compiler that
 * `pip install` already uses; the build is optional (setup.py), and without it the estimator
 * runs the reference backend (backend.py's PythonBackend), which tests hold equal to this one.
 *
 * What is here is the EKF's linear algebra and, as the one model that runs on every message, the
 * motion model's prediction and the orientation observation; the other measurement models stay
 * in Python. The maths is exactly that of the reference backend's propagate / update
 * (backend.py's PythonBackend, ekf.py's docstrings derive it), of StateLayout.boxplus for
 * the layout where every block after the pose is additive, of motion.predict and of
 * observations.orientation:
 *
 *   predict:    motion.predict for input blocks of the kinds listed under BLOCK_* (the classes
 *               name theirs in kernel_code): each block's correction of its input, x' (the pose
 *               moved by the twist and the rate), F (the cross block and the blocks' columns by the
 *               chain rule) and Q: its diagonal (noise density * dt) and the input-noise blocks
 *               scale * G S G^T of the odometry twist and the gyro rate (motion.py's _input_noise,
 *               same expressions); a layout with any other block predicts in Python.
 *               tests/unit/test_kernels.py holds x', F and Q to the Python path's bits.
 *   orientation: observations.orientation's innovation and Jacobian (rpy_jacobian, rot.wrap), the
 *               IMU's most frequent update.
 *   line_fit:   line_fit.line_fit, the odometry's forward acceleration (a least-squares slope over
 *               half a second of speeds, taken at every odometry message when an IMU reads tilt
 *               from gravity): the same sums in the same order, the same doubles.
 *   propagate:  P' = (F P) F^T + Q, finite iff its diagonal sums to a finite number.
 *   update:     HP = H P, S = HP H^T + R = L L^T (Cholesky), z = L^-1 y, NIS = z.z,
 *               W = L^-1 HP, dx = HP^T L^-T z, P' = P - W^T W; with a mask (Schmidt update),
 *               dx *= keep and W^T W *= J elementwise (the Joseph form's closed form); then
 *               x [+]= dx: p += dp, q = normalize(Exp(dtheta) q), x_i += dx_(i-1) after the
 *               quaternion, and with hold_heading the yaw put back (state.hold_heading_of).
 *   difference_noise, zero_mean_window: zero_motion.py's, the odometry's standstill test at every
 *               odometry message (its running noise and its window's test, ~2 us of tuples in Python).
 *   rts_fold:   the smoother's fold of a run of transitions (smoother.py; the reference: rts.py): A P0 F^T P1^-1 on
 *               the components P1 gives any variance, by a Cholesky solve; paid per correction and per
 *               output moment while a smoother records, ~30 us of numpy and LAPACK calls otherwise.
 *
 * The scalar expressions of the quaternion code are written in the same order as rotation.py's
 * (and compiled with -ffp-contract=off, setup.py), so they give the same doubles; the matrix
 * products differ from OpenBLAS's only in summation order (a few ulps).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define MAX_N 48 /* error dimension handled here; larger layouts run the reference backend */
#define MAX_M 12 /* measurement rows */

/* Status codes of update(), mirrored in backend.py. */
enum { APPLIED = 0, GATED = 1, SINGULAR = 2, NEEDS_CHECK = 3 };

/* -- buffers --------------------------------------------------------------------------------- */

/* A C-contiguous float64 buffer of exactly `count` items (or any count when count < 0). An array
 * that cannot be read so (another dtype or order) is a BufferError, which the compiled backend
 * (backend.py) answers with the reference; a wrong size is a ValueError (a caller's bug). */
static int get_doubles(PyObject *obj, Py_buffer *view, int writable, Py_ssize_t count, const char *what) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0) {
        PyErr_Clear();
        PyErr_Format(PyExc_BufferError, "%s must be a C-contiguous%s float64 array", what,
                     writable ? " writable" : "");
        return -1;
    }
    if (view->itemsize != 8 || view->format == NULL || strcmp(view->format, "d") != 0) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_BufferError, "%s must be a C-contiguous float64 array", what);
        return -1;
    }
    if (count >= 0 && view->len != count * 8) {
        PyBuffer_Release(view);
        PyErr_Format(PyExc_ValueError, "%s has %zd values, expected %zd", what, view->len / 8, count);
        return -1;
    }
    return 0;
}

/* The buffers one call holds, acquired in turn and released together: a call checks every array
 * before it writes anything, and leaves by one exit that releases what it got. */
typedef struct {
    Py_buffer view[8];
    int count;
} Held;

/* The data of `obj` as get_doubles checks it, kept in `held`; NULL with the exception set. */
static double *hold(Held *held, PyObject *obj, int writable, Py_ssize_t count, const char *what) {
    Py_buffer *v = &held->view[held->count];
    if (get_doubles(obj, v, writable, count, what) < 0) {
        return NULL;
    }
    held->count++;
    return v->buf;
}

/* Items of the buffer held last. */
static Py_ssize_t last_items(const Held *held) {
    return held->view[held->count - 1].len / 8;
}

static void release(Held *held) {
    while (held->count > 0) {
        PyBuffer_Release(&held->view[--held->count]);
    }
}

/* n for an n x n matrix of `items` values with min_n <= n <= MAX_N, else -1 with a ValueError naming it. */
static Py_ssize_t square_side(Py_ssize_t items, Py_ssize_t min_n, const char *what) {
    Py_ssize_t n = (Py_ssize_t)(sqrt((double)items) + 0.5);
    if (n * n != items || n < min_n || n > MAX_N) {
        PyErr_Format(PyExc_ValueError, "%s must be square with %zd to %d rows", what, min_n, MAX_N);
        return -1;
    }
    return n;
}

/* -- quaternions (rotation.py, same expressions) ------------------------------------------------ */

static int normalize4(double *q) {
    double n = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    if (!(n > 0.0) || !isfinite(n)) {
        return -1;
    }
    q[0] = q[0] / n;
    q[1] = q[1] / n;
    q[2] = q[2] / n;
    q[3] = q[3] / n;
    return 0;
}

/* rotation.exp */
static int quat_exp(double vx, double vy, double vz, double *out) {
    double angle = sqrt(vx * vx + vy * vy + vz * vz);
    if (angle < 1e-8) {
        out[0] = 0.5 * vx;
        out[1] = 0.5 * vy;
        out[2] = 0.5 * vz;
        out[3] = 1.0 - angle * angle / 8.0;
        return normalize4(out);
    }
    double s = sin(0.5 * angle) / angle;
    out[0] = vx * s;
    out[1] = vy * s;
    out[2] = vz * s;
    out[3] = cos(0.5 * angle);
    return 0;
}

/* rotation.mul */
static void quat_mul(const double *a, const double *b, double *out) {
    double ax = a[0], ay = a[1], az = a[2], aw = a[3];
    double bx = b[0], by = b[1], bz = b[2], bw = b[3];
    out[0] = aw * bx + ax * bw + ay * bz - az * by;
    out[1] = aw * by - ax * bz + ay * bw + az * bx;
    out[2] = aw * bz + ax * by - ay * bx + az * bw;
    out[3] = aw * bw - ax * bx - ay * by - az * bz;
}

/* rotation._mul_unit: normalize(mul(a, b)) */
static int mul_unit(const double *a, const double *b, double *out) {
    quat_mul(a, b, out);
    return normalize4(out);
}

static double quat_yaw(const double *q) {
    double x = q[0], y = q[1], z = q[2], w = q[3];
    return atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
}

/* rotation.wrap: (angle + pi) % 2pi - pi with Python's float modulo (the sign of the divisor) */
static double wrap_angle(double angle) {
    const double two_pi = 2.0 * M_PI;
    double a = angle + M_PI;
    double mod = fmod(a, two_pi);
    if (mod != 0.0) {
        if (mod < 0.0) {
            mod += two_pi;
        }
    } else {
        mod = copysign(0.0, two_pi);
    }
    return mod - M_PI;
}

/* StateLayout.boxplus with an additive tail; hold_heading as state.hold_heading_of. x is written only
 * once everything is computed, so a failure (a zero quaternion) leaves it as it was, as in Python. */
static int boxplus(double *x, Py_ssize_t nx, const double *dx, int hold_heading) {
    double heading = 0.0, turned[4], dq[4];
    if (hold_heading) {
        heading = quat_yaw(x + 3);
    }
    if (quat_exp(dx[3], dx[4], dx[5], dq) < 0 || mul_unit(dq, x + 3, turned) < 0) {
        return -1;
    }
    if (hold_heading) {
        double back[4]; /* hold_heading_of: mul(exp(0, 0, wrap(heading - yaw(q))), q), not renormalised */
        if (quat_exp(0.0, 0.0, wrap_angle(heading - quat_yaw(turned)), dq) < 0) {
            return -1;
        }
        quat_mul(dq, turned, back);
        memcpy(turned, back, sizeof(back));
    }
    x[0] += dx[0];
    x[1] += dx[1];
    x[2] += dx[2];
    memcpy(x + 3, turned, sizeof(turned));
    for (Py_ssize_t i = 7; i < nx; i++) {
        x[i] += dx[i - 1];
    }
    return 0;
}

/* -- small sequences and Q's noise blocks ----------------------------------------------------- */

/* `count` doubles from a sequence of as many floats (a 3-vector, or a row-major 3x3 as the motion model
 * keeps them). */
static int doubles(PyObject *seq, double *out, Py_ssize_t count, const char *what) {
    PyObject *fast = PySequence_Fast(seq, what);
    if (fast == NULL) {
        return -1;
    }
    if (PySequence_Fast_GET_SIZE(fast) != count) {
        Py_DECREF(fast);
        PyErr_Format(PyExc_ValueError, "%s must have %zd entries", what, count);
        return -1;
    }
    PyObject **items = PySequence_Fast_ITEMS(fast);
    for (Py_ssize_t i = 0; i < count; i++) {
        out[i] = PyFloat_AsDouble(items[i]);
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(fast);
            return -1;
        }
    }
    Py_DECREF(fast);
    return 0;
}

/* The off-diagonal entries (k, k+1), (k, k+2), (k+1, k+2) of Q's 3x3 block at k, and their mirrors. */
static void noise_off_diagonal(double *Q, Py_ssize_t n, Py_ssize_t k, double c01, double c02, double c12) {
    Q[k * n + k + 1] = Q[(k + 1) * n + k] = c01;
    Q[k * n + k + 2] = Q[(k + 2) * n + k] = c02;
    Q[(k + 1) * n + k + 2] = Q[(k + 2) * n + k + 1] = c12;
}

/* motion._input_noise for one input: scale * G S G^T (mat3.sandwich, or mat3.sandwich_diag for a
 * diagonal S: the same expressions, so the same doubles), its diagonal added into q[k..k+2]
 * (c + q, in that order), its off-diagonals written at (k, k+1), (k, k+2), (k+1, k+2) and mirrors. */
static void input_block(double *Q, Py_ssize_t n, double *q, int k, const double *a, const double *s, double scale) {
    double m[9];
    if (s[1] == 0.0 && s[2] == 0.0 && s[3] == 0.0 && s[5] == 0.0 && s[6] == 0.0 && s[7] == 0.0) {
        m[0] = a[0] * s[0], m[1] = a[1] * s[4], m[2] = a[2] * s[8];
        m[3] = a[3] * s[0], m[4] = a[4] * s[4], m[5] = a[5] * s[8];
        m[6] = a[6] * s[0], m[7] = a[7] * s[4], m[8] = a[8] * s[8];
    } else {
        for (int r = 0; r < 3; r++) {
            for (int c = 0; c < 3; c++) {
                m[3 * r + c] = a[3 * r] * s[c] + a[3 * r + 1] * s[3 + c] + a[3 * r + 2] * s[6 + c];
            }
        }
    }
    double c00 = (m[0] * a[0] + m[1] * a[1] + m[2] * a[2]) * scale;
    double c01 = (m[0] * a[3] + m[1] * a[4] + m[2] * a[5]) * scale;
    double c02 = (m[0] * a[6] + m[1] * a[7] + m[2] * a[8]) * scale;
    double c11 = (m[3] * a[3] + m[4] * a[4] + m[5] * a[5]) * scale;
    double c12 = (m[3] * a[6] + m[4] * a[7] + m[5] * a[8]) * scale;
    double c22 = (m[6] * a[6] + m[7] * a[7] + m[8] * a[8]) * scale;
    q[k] = c00 + q[k];
    q[k + 1] = c11 + q[k + 1];
    q[k + 2] = c22 + q[k + 2];
    noise_off_diagonal(Q, n, k, c01, c02, c12);
}

/* -- motion model ----------------------------------------------------------------------------- */

/* The input blocks the motion model knows in C, by their class's kernel_code (state.py, scale.py,
 * twist_pitch.py): each one's correct / chain / input_derivative, the same expressions. A layout with
 * any other input block takes motion.py's Python path. */
enum { BLOCK_GYRO_BIAS = 1, BLOCK_WHEEL_SCALE = 2, BLOCK_GYRO_SCALE = 3, BLOCK_TWIST_PITCH = 4 };
#define MAX_INPUT_BLOCKS 8

typedef struct {
    int code, applies, linear; /* linear: corrects the twist (F rows 0-2), else the rate (rows 3-5) */
    Py_ssize_t n0, c0, size;    /* nominal index, first error column, error size */
    double xb[3];               /* the block's nominal values this step */
    double u_in[3];             /* the input as it reached the block */
} MotionBlock;

/* mat3.mul: k * A B, row-major */
static void mat3_mul(const double *a, const double *b, double k, double *out) {
    double r[9];
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            r[3 * i + j] = (a[3 * i] * b[j] + a[3 * i + 1] * b[3 + j] + a[3 * i + 2] * b[6 + j]) * k;
        }
    }
    memcpy(out, r, sizeof(r));
}

/* rotation.matrix9 */
static void quat_matrix9(const double *q, double *R) {
    double x = q[0], y = q[1], z = q[2], w = q[3];
    double xx = x * x, yy = y * y, zz = z * z, xy = x * y, xz = x * z, yz = y * z, wx = w * x, wy = w * y, wz = w * z;
    R[0] = 1.0 - 2.0 * (yy + zz), R[1] = 2.0 * (xy - wz), R[2] = 2.0 * (xz + wy);
    R[3] = 2.0 * (xy + wz), R[4] = 1.0 - 2.0 * (xx + zz), R[5] = 2.0 * (yz - wx);
    R[6] = 2.0 * (xz - wy), R[7] = 2.0 * (yz + wx), R[8] = 1.0 - 2.0 * (xx + yy);
}

/* motion._right_jacobian */
static void right_jacobian(double x, double y, double z, double *J) {
    double t2 = x * x + y * y + z * z, a, b;
    if (t2 < 1e-10) {
        a = 0.5, b = 1.0 / 6.0;
    } else {
        double t = sqrt(t2);
        a = (1.0 - cos(t)) / t2;
        b = (t - sin(t)) / (t2 * t);
    }
    J[0] = 1.0 + b * (x * x - t2), J[1] = a * z + b * x * y, J[2] = -a * y + b * x * z;
    J[3] = -a * z + b * x * y, J[4] = 1.0 + b * (y * y - t2), J[5] = a * x + b * y * z;
    J[6] = a * y + b * x * z, J[7] = -a * x + b * y * z, J[8] = 1.0 + b * (z * z - t2);
}

/* InputBlock.correct of each kind: u' from u (u_out may be u) */
static void block_correct(const MotionBlock *blk, const double *u, double *u_out) {
    double u0 = u[0], u1 = u[1], u2 = u[2], s = blk->xb[0];
    switch (blk->code) {
    case BLOCK_GYRO_BIAS:
        u_out[0] = u0 - blk->xb[0], u_out[1] = u1 - blk->xb[1], u_out[2] = u2 - blk->xb[2];
        break;
    case BLOCK_WHEEL_SCALE:
        u_out[0] = s * u0, u_out[1] = s * u1, u_out[2] = s * u2;
        break;
    case BLOCK_GYRO_SCALE:
        u_out[0] = u0, u_out[1] = u1, u_out[2] = s * u2;
        break;
    case BLOCK_TWIST_PITCH: {
        double c = cos(s), sn = sin(s);
        u_out[0] = c * u0 - sn * u2, u_out[1] = u1, u_out[2] = sn * u0 + c * u2;
        break;
    }
    }
}

/* InputBlock.chain (this block's 3 x size columns of F, row-major) and, for the blocks that scale their
 * input (scales_input), G = mat3.mul(G, input_derivative). */
static void block_chain(const MotionBlock *blk, double *G, double *columns) {
    const double *u = blk->u_in;
    double s = blk->xb[0], d[9];
    switch (blk->code) {
    case BLOCK_GYRO_BIAS:
        for (int i = 0; i < 9; i++) {
            columns[i] = -G[i];
        }
        return;
    case BLOCK_WHEEL_SCALE:
        columns[0] = G[0] * u[0] + G[1] * u[1] + G[2] * u[2];
        columns[1] = G[3] * u[0] + G[4] * u[1] + G[5] * u[2];
        columns[2] = G[6] * u[0] + G[7] * u[1] + G[8] * u[2];
        d[0] = s, d[1] = 0.0, d[2] = 0.0, d[3] = 0.0, d[4] = s, d[5] = 0.0, d[6] = 0.0, d[7] = 0.0, d[8] = s;
        break;
    case BLOCK_GYRO_SCALE:
        columns[0] = G[2] * u[2], columns[1] = G[5] * u[2], columns[2] = G[8] * u[2];
        d[0] = 1.0, d[1] = 0.0, d[2] = 0.0, d[3] = 0.0, d[4] = 1.0, d[5] = 0.0, d[6] = 0.0, d[7] = 0.0, d[8] = s;
        break;
    case BLOCK_TWIST_PITCH: {
        double c = cos(s), sn = sin(s);
        double a = -sn * u[0] - c * u[2], b = c * u[0] - sn * u[2];
        columns[0] = G[0] * a + G[2] * b, columns[1] = G[3] * a + G[5] * b, columns[2] = G[6] * a + G[8] * b;
        d[0] = c, d[1] = 0.0, d[2] = -sn, d[3] = 0.0, d[4] = 1.0, d[5] = 0.0, d[6] = sn, d[7] = 0.0, d[8] = c;
        break;
    }
    default:
        return;
    }
    mat3_mul(G, d, 1.0, G);
}

/* A tuple of `count` ints into out (PyArg_ParseTuple's format parsing cost as much as the rest of a
 * prediction's argument handling, once per block and call). */
static int ints(PyObject *tuple, Py_ssize_t *out, Py_ssize_t count, const char *what) {
    if (!PyTuple_Check(tuple) || PyTuple_GET_SIZE(tuple) != count) {
        PyErr_Format(PyExc_TypeError, "%s must be a tuple of %zd ints", what, count);
        return -1;
    }
    for (Py_ssize_t i = 0; i < count; i++) {
        out[i] = PyLong_AsSsize_t(PyTuple_GET_ITEM(tuple, i));
    }
    return PyErr_Occurred() ? -1 : 0;
}

/* The layout's input blocks, a tuple of (code, applies, linear, n0, c0, size) tuples, into blocks. */
static Py_ssize_t read_blocks(PyObject *spec, MotionBlock *blocks, Py_ssize_t nx, Py_ssize_t n) {
    if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) > MAX_INPUT_BLOCKS) {
        PyErr_Format(PyExc_ValueError, "blocks must be a tuple of at most %d entries", MAX_INPUT_BLOCKS);
        return -1;
    }
    Py_ssize_t count = PyTuple_GET_SIZE(spec);
    for (Py_ssize_t i = 0; i < count; i++) {
        MotionBlock *b = &blocks[i];
        Py_ssize_t f[6];
        if (ints(PyTuple_GET_ITEM(spec, i), f, 6, "an input block") < 0) {
            return -1;
        }
        Py_ssize_t code = f[0];
        b->applies = f[1] != 0, b->linear = f[2] != 0, b->n0 = f[3], b->c0 = f[4], b->size = f[5];
        b->code = (int)code;
        Py_ssize_t expected = code == BLOCK_GYRO_BIAS ? 3 : 1;
        if (code < BLOCK_GYRO_BIAS || code > BLOCK_TWIST_PITCH || b->size != expected || b->n0 < 7 ||
            b->n0 + b->size > nx || b->c0 < 6 || b->c0 + b->size > n) {
            PyErr_SetString(PyExc_ValueError, "an input block outside the state, or of an unknown kind");
            return -1;
        }
    }
    return count;
}

/* A Gauss-Markov error block (gps_error.GpsErrorBlock): x' = a x and F's diagonal a with a = exp(-dt / tau),
 * its discrete noise var_i (1 - exp(-2 dt / tau)) added to Q's diagonal; the block's own expressions. */
#define MAX_DECAY_BLOCKS 4
typedef struct {
    Py_ssize_t n0, e0, size;
    double tau, var[3];
} DecayBlock;

/* ((n0, e0, tau, (var, ...)), ...) into decays; their count, or -1 with an exception set. */
static Py_ssize_t read_decays(PyObject *spec, DecayBlock *decays, Py_ssize_t nx, Py_ssize_t n) {
    if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) > MAX_DECAY_BLOCKS) {
        PyErr_Format(PyExc_ValueError, "decays must be a tuple of at most %d entries", MAX_DECAY_BLOCKS);
        return -1;
    }
    Py_ssize_t count = PyTuple_GET_SIZE(spec);
    for (Py_ssize_t i = 0; i < count; i++) {
        DecayBlock *b = &decays[i];
        PyObject *entry = PyTuple_GET_ITEM(spec, i), *var;
        if (!PyTuple_Check(entry) || PyTuple_GET_SIZE(entry) != 4 || !PyTuple_Check(var = PyTuple_GET_ITEM(entry, 3))) {
            PyErr_SetString(PyExc_TypeError, "a decaying block must be (n0, e0, tau, (var, ...))");
            return -1;
        }
        b->n0 = PyLong_AsSsize_t(PyTuple_GET_ITEM(entry, 0));
        b->e0 = PyLong_AsSsize_t(PyTuple_GET_ITEM(entry, 1));
        b->tau = PyFloat_AsDouble(PyTuple_GET_ITEM(entry, 2));
        if (PyErr_Occurred()) {
            return -1;
        }
        b->size = PyTuple_GET_SIZE(var);
        if (b->size < 1 || b->size > 3 || b->n0 < 7 || b->n0 + b->size > nx || b->e0 < 6 || b->e0 + b->size > n) {
            PyErr_SetString(PyExc_ValueError, "a decaying block outside the state");
            return -1;
        }
        for (Py_ssize_t k = 0; k < b->size; k++) {
            b->var[k] = PyFloat_AsDouble(PyTuple_GET_ITEM(var, k));
        }
        if (PyErr_Occurred()) {
            return -1;
        }
    }
    return count;
}

/* Does a kernel get the arguments it takes (`low` to `high`)? Else a TypeError naming its call and the count
 * given, as Python's own for a function, and 0: the kernel returns NULL. */
static int takes(Py_ssize_t nargs, Py_ssize_t low, Py_ssize_t high, const char *call) {
    if (low <= nargs && nargs <= high) {
        return 1;
    }
    if (low == high) {
        PyErr_Format(PyExc_TypeError, "%s takes %zd argument%s (%zd given)", call, low, low == 1 ? "" : "s", nargs);
    } else {
        PyErr_Format(PyExc_TypeError, "%s takes %zd or %zd arguments (%zd given)", call, low, high, nargs);
    }
    return 0;
}

PyDoc_STRVAR(predict_doc,
"predict(x, x_out, F, Q, density, dt, extra, linear, angular, linear_cov, angular_cov, linear_period,\n"
"        angular_period, twist_correlation, flags, blocks[, decays]) -> None\n\n"
"motion.predict for a layout whose input blocks all have a kernel_code: x_out (nominal, as long as\n"
"x) gets the propagated pose and x's other entries, F (n x n, the identity elsewhere) its cross\n"
"block and the input blocks' columns, Q the entries motion.PredictWorkspace lists (its diagonal, the\n"
"input-noise blocks' off-diagonals; the others untouched). flags: 1 world-frame twist,\n"
"2 planar rates. blocks: (code, applies, linear, n0, c0, size) per input block in layout order.\n"
"decays: ((n0, e0, tau, (var, ...)), ...), the Gauss-Markov blocks, whose decay and noise are then\n"
"written here (x' = a x, F's diagonal a, Q's diagonal var (1 - exp(-2 dt / tau)) beside density * dt);\n"
"without it the dynamic blocks' decay is left to the caller (their noise comes in extra, or None).");

static PyObject *predict(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 16, 17, "predict")) {
        return NULL;
    }
    double dt = PyFloat_AsDouble(args[5]);
    double lin_period = PyFloat_AsDouble(args[11]), ang_period = PyFloat_AsDouble(args[12]);
    double tau = PyFloat_AsDouble(args[13]);
    long flags = PyLong_AsLong(args[14]);
    double v[3], w[3], cov[2][9];
    if (PyErr_Occurred() || doubles(args[7], v, 3, "linear") < 0 || doubles(args[8], w, 3, "angular") < 0 ||
        doubles(args[9], cov[0], 9, "linear_cov") < 0 || doubles(args[10], cov[1], 9, "angular_cov") < 0) {
        return NULL;
    }
    Held held = {.count = 0};
    const double *x = NULL, *d = NULL, *extra = NULL;
    double *x_out = NULL, *F = NULL, *Q = NULL;
    Py_ssize_t nx = -1, n = -1;
    MotionBlock blocks[MAX_INPUT_BLOCKS];
    if ((x = hold(&held, args[0], 0, -1, "x")) == NULL) {
        goto fail;
    }
    nx = last_items(&held);
    if ((x_out = hold(&held, args[1], 1, nx, "x_out")) == NULL || (F = hold(&held, args[2], 1, -1, "F")) == NULL ||
        (n = square_side(last_items(&held), 6, "F")) < 0 || (Q = hold(&held, args[3], 1, n * n, "Q")) == NULL ||
        (d = hold(&held, args[4], 0, n, "density")) == NULL ||
        (args[6] != Py_None && (extra = hold(&held, args[6], 0, n, "extra")) == NULL)) {
        goto fail;
    }
    if (nx < 7 || nx - 1 > n) {
        PyErr_SetString(PyExc_ValueError, "x must hold a pose and fit F");
        goto fail;
    }
    Py_ssize_t count = read_blocks(args[15], blocks, nx, n);
    if (count < 0) {
        goto fail;
    }
    DecayBlock decays[MAX_DECAY_BLOCKS];
    Py_ssize_t n_decays = nargs == 17 ? read_decays(args[16], decays, nx, n) : 0;
    if (n_decays < 0) {
        goto fail;
    }
    /* the input blocks correct the inputs in layout order, each keeping the input it saw */
    for (Py_ssize_t i = 0; i < count; i++) {
        MotionBlock *b = &blocks[i];
        if (!b->applies) {
            continue;
        }
        memcpy(b->xb, x + b->n0, sizeof(double) * (size_t)b->size);
        double *u = b->linear ? v : w;
        memcpy(b->u_in, u, sizeof(b->u_in));
        block_correct(b, u, u);
    }
    double q[4] = {x[3], x[4], x[5], x[6]}, R[9], G_lin[9], G_ang[9], Jr[9], dp[3], q1[4], e[4];
    quat_matrix9(q, R);
    if (flags & 1) {
        for (int i = 0; i < 9; i++) {
            G_lin[i] = (i % 4 == 0) ? dt : 0.0;
        }
        dp[0] = v[0] * dt, dp[1] = v[1] * dt, dp[2] = v[2] * dt;
    } else {
        for (int i = 0; i < 9; i++) {
            G_lin[i] = R[i] * dt;
        }
        for (int i = 0; i < 3; i++) {
            dp[i] = (R[3 * i] * v[0] + R[3 * i + 1] * v[1] + R[3 * i + 2] * v[2]) * dt;
        }
    }
    if (flags & 2) {
        w[0] = 0.0, w[1] = 0.0;
    }
    double ax = w[0] * dt, ay = w[1] * dt, az = w[2] * dt;
    if (quat_exp(ax, ay, az, e) < 0 || mul_unit(q, e, q1) < 0) {
        PyErr_SetString(PyExc_ArithmeticError, "quaternion has zero or non-finite norm");
        goto fail;
    }
    /* d theta' / d w = R Jl(w dt) dt, Jl(phi) = Jr(-phi); planar: the x/y columns go */
    right_jacobian(-ax, -ay, -az, Jr);
    mat3_mul(R, Jr, dt, G_ang);
    if (flags & 2) {
        G_ang[0] = G_ang[1] = G_ang[3] = G_ang[4] = G_ang[6] = G_ang[7] = 0.0;
    }
    /* F: the cross block -[dp]x (zero for a world-frame twist), then each input block's columns,
     * walking the blocks backwards and carrying G through those that scale their input */
    int world = (flags & 1) != 0;
    F[0 * n + 4] = world ? 0.0 : dp[2], F[0 * n + 5] = world ? 0.0 : -dp[1];
    F[1 * n + 3] = world ? 0.0 : -dp[2], F[1 * n + 5] = world ? 0.0 : dp[0];
    F[2 * n + 3] = world ? 0.0 : dp[1], F[2 * n + 4] = world ? 0.0 : -dp[0];
    for (Py_ssize_t i = count - 1; i >= 0; i--) {
        MotionBlock *b = &blocks[i];
        double columns[9] = {0.0};
        if (b->applies) {
            block_chain(b, b->linear ? G_lin : G_ang, columns);
        }
        Py_ssize_t r0 = b->linear ? 0 : 3;
        for (Py_ssize_t r = 0; r < 3; r++) {
            for (Py_ssize_t c = 0; c < b->size; c++) {
                F[(r0 + r) * n + b->c0 + c] = columns[r * b->size + c];
            }
        }
    }
    /* Q: density * dt (+ extra) and the decays' noise on the diagonal, each held input's noise block
     * scale * G cov G^T (the odometry's period widened to its correlation, motion.py's module doc);
     * without time (dt = 0) every written entry is 0 */
    int noisy = dt > 0.0;
    double qd[MAX_N];
    for (Py_ssize_t i = 0; i < n; i++) {
        qd[i] = 0.0;
        if (noisy) {
            qd[i] = d[i] * dt;
            if (extra != NULL) {
                qd[i] += extra[i];
            }
        }
    }
    for (Py_ssize_t j = 0; noisy && j < n_decays; j++) { /* GpsErrorBlock.process_noise: k = 1 - exp(-2 dt / tau) */
        DecayBlock *b = &decays[j];
        double k = -expm1(-2.0 * dt / b->tau);
        for (Py_ssize_t i = 0; i < b->size; i++) {
            double add = b->var[i] * k;
            qd[b->e0 + i] += add;
        }
    }
    const double *gs[2] = {G_lin, G_ang};
    double periods[2] = {lin_period, ang_period};
    for (int j = 0; j < 2; j++) {
        int k = 3 * j;
        if (noisy && periods[j] > 0.0) {
            double period = periods[j];
            if (j == 0 && 2.0 * tau > period) { /* Python's max(period, 2 tau) */
                period = 2.0 * tau;
            }
            input_block(Q, n, qd, k, gs[j], cov[j], period / dt);
        } else {
            noise_off_diagonal(Q, n, k, 0.0, 0.0, 0.0);
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        Q[i * n + i] = qd[i];
    }
    /* x_out last: x may be x_out */
    double head[7] = {x[0] + dp[0], x[1] + dp[1], x[2] + dp[2], q1[0], q1[1], q1[2], q1[3]};
    if (x_out != x) {
        memcpy(x_out + 7, x + 7, sizeof(double) * (size_t)(nx - 7));
    }
    memcpy(x_out, head, sizeof(head));
    for (Py_ssize_t j = 0; j < n_decays; j++) { /* GpsErrorBlock.transition: a = exp(-dt / tau) */
        DecayBlock *b = &decays[j];
        double a = exp(-dt / b->tau);
        for (Py_ssize_t i = 0; i < b->size; i++) {
            x_out[b->n0 + i] *= a;
            F[(b->e0 + i) * n + b->e0 + i] = a;
        }
    }
    release(&held);
    Py_RETURN_NONE;
fail:
    release(&held);
    return NULL;
}

/* -- orientation observation ------------------------------------------------------------------ */

/* observations.rpy_jacobian: (roll, pitch, yaw) of q and their rows of d(rpy)/d(global dtheta), the
 * same expressions (Python's min/max written out with their comparisons, for the same NaN behaviour) */
static void rpy_jacobian(const double *q, double *rpy, double *Hrpy) {
    const double min_cos_pitch = 1e-3;
    double r[9];
    quat_matrix9(q, r);
    double r00 = r[0], r01 = r[1], r02 = r[2], r10 = r[3], r11 = r[4], r12 = r[5], r20 = r[6], r21 = r[7], r22 = r[8];
    double roll = atan2(r21, r22);
    double sp = -r20 < 1.0 ? -r20 : 1.0;     /* min(1.0, -r20) */
    double pitch = asin(sp > -1.0 ? sp : -1.0); /* max(-1.0, .) */
    double yaw = atan2(r10, r00);
    double c = cos(pitch);
    double cp = min_cos_pitch > c ? min_cos_pitch : c;
    double cr = cos(roll), sr = sin(roll);
    double c2 = r00 * r00 + r10 * r10, floor2 = pow(min_cos_pitch, 2.0); /* Python's 1e-3**2 */
    if (floor2 > c2) {
        c2 = floor2;
    }
    rpy[0] = roll, rpy[1] = pitch, rpy[2] = yaw;
    Hrpy[0] = (cr * r11 - sr * r12) / cp, Hrpy[1] = (cr * -r01 - sr * -r02) / cp, Hrpy[2] = 0.0;
    Hrpy[3] = -r10 / cp, Hrpy[4] = -(-r00) / cp, Hrpy[5] = 0.0;
    Hrpy[6] = -r00 * r20 / c2, Hrpy[7] = -r10 * r20 / c2, Hrpy[8] = 1.0;
}

PyDoc_STRVAR(orientation_doc,
"orientation(x, z_rpy, rows, y, H) -> None\n\n"
"observations.orientation's innovation and Jacobian: for each of rows (roll 0, pitch 1, yaw 2) in\n"
"order, y[k] = wrap(z_rpy[i] - rpy(q)[i]) and H's row k d(rpy_i)/d(global dtheta) in columns 3-5,\n"
"zero elsewhere. x the nominal state (q at 3-6), y (m) and H (m x n) written whole.");

static PyObject *orientation(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 5, 5, "orientation")) {
        return NULL;
    }
    double z[3];
    int rows[3];
    if (doubles(args[1], z, 3, "z_rpy") < 0) {
        return NULL;
    }
    PyObject *fast = PySequence_Fast(args[2], "rows");
    if (fast == NULL) {
        return NULL;
    }
    Py_ssize_t m = PySequence_Fast_GET_SIZE(fast);
    for (Py_ssize_t k = 0; k < m && k < 3; k++) {
        long i = PyLong_AsLong(PySequence_Fast_ITEMS(fast)[k]);
        rows[k] = (int)i;
        if ((i == -1 && PyErr_Occurred()) || i < 0 || i > 2) {
            Py_DECREF(fast);
            if (!PyErr_Occurred()) {
                PyErr_SetString(PyExc_ValueError, "rows must be among 0, 1, 2");
            }
            return NULL;
        }
    }
    Py_DECREF(fast);
    if (m < 1 || m > 3) {
        PyErr_SetString(PyExc_ValueError, "rows must have 1 to 3 entries");
        return NULL;
    }
    Held held = {.count = 0};
    const double *x = hold(&held, args[0], 0, -1, "x");
    double *y = NULL, *H = NULL;
    Py_ssize_t n = 0;
    if (x == NULL) {
        goto fail;
    }
    if (last_items(&held) < 7) {
        PyErr_SetString(PyExc_ValueError, "x must hold a pose");
        goto fail;
    }
    if ((y = hold(&held, args[3], 1, m, "y")) == NULL || (H = hold(&held, args[4], 1, -1, "H")) == NULL) {
        goto fail;
    }
    n = last_items(&held) / m;
    if (n * m != last_items(&held) || n < 6) {
        PyErr_SetString(PyExc_ValueError, "H must have len(rows) rows of at least 6 columns");
        goto fail;
    }
    double rpy[3], Hrpy[9];
    rpy_jacobian(x + 3, rpy, Hrpy);
    memset(H, 0, sizeof(double) * (size_t)(m * n));
    for (Py_ssize_t k = 0; k < m; k++) {
        int i = rows[k];
        y[k] = wrap_angle(z[i] - rpy[i]);
        H[k * n + 3] = Hrpy[3 * i], H[k * n + 4] = Hrpy[3 * i + 1], H[k * n + 5] = Hrpy[3 * i + 2];
    }
    release(&held);
    Py_RETURN_NONE;
fail:
    release(&held);
    return NULL;
}

/* -- small writes a prediction makes ---------------------------------------------------------- */

PyDoc_STRVAR(add_motion_noise_doc,
"add_motion_noise(Q, xx, xy, yy, yaw_row, yaw) -> None\n\n"
"state.add_motion_noise in one call: Q[0,0] += xx, Q[0,1] and Q[1,0] += xy, Q[1,1] += yy,\n"
"Q[yaw_row, yaw_row] += yaw (Q: an n x n float64 array; the same additions, so the same doubles).");

static PyObject *add_motion_noise(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 6, 6, "add_motion_noise(Q, xx, xy, yy, yaw_row, yaw)")) {
        return NULL;
    }
    double xx = PyFloat_AsDouble(args[1]), xy = PyFloat_AsDouble(args[2]), yy = PyFloat_AsDouble(args[3]);
    Py_ssize_t yaw_row = PyLong_AsSsize_t(args[4]);
    double yaw = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) {
        return NULL;
    }
    Held held = {.count = 0};
    double *Q = hold(&held, args[0], 1, -1, "Q");
    Py_ssize_t n = Q == NULL ? -1 : square_side(last_items(&held), 2, "Q");
    if (n < 0 || yaw_row < 0 || yaw_row >= n) {
        if (n >= 0) {
            PyErr_SetString(PyExc_ValueError, "yaw_row outside Q");
        }
        release(&held);
        return NULL;
    }
    Q[0] += xx;
    Q[1] += xy;
    Q[n] += xy;
    Q[n + 1] += yy;
    Q[yaw_row * n + yaw_row] += yaw;
    release(&held);
    Py_RETURN_NONE;
}

/* A tuple of at most MAX_N ints into out: their count, or -1 with a TypeError. */
static Py_ssize_t indices(PyObject *tuple, Py_ssize_t *out, const char *what) {
    Py_ssize_t count = PyTuple_Check(tuple) ? PyTuple_GET_SIZE(tuple) : -1;
    if (count < 0 || count > MAX_N) {
        PyErr_SetString(PyExc_TypeError, "nominal_zero and error_zero must be tuples of ints");
        return -1;
    }
    return count == 0 || ints(tuple, out, count, what) == 0 ? count : -1;
}

/* Does every one of the count indices lie in [0, limit)? Else a ValueError saying `outside`. */
static int within(const Py_ssize_t *idx, Py_ssize_t count, Py_ssize_t limit, const char *outside) {
    for (Py_ssize_t k = 0; k < count; k++) {
        if (idx[k] < 0 || idx[k] >= limit) {
            PyErr_SetString(PyExc_ValueError, outside);
            return 0;
        }
    }
    return 1;
}

PyDoc_STRVAR(hold_planar_doc,
"hold_planar(x, P, nominal_zero, error_zero) -> None\n\n"
"ErrorStateEKF.hold_planar's writes in one call: the attitude x[3:7] turned into the rotation about z\n"
"with its heading (the reference's expressions, so the same doubles), x[i] = 0 for i in nominal_zero,\n"
"and P's rows and columns of error_zero zeroed (both tuples of ints, checked before anything is written).");

static PyObject *hold_planar(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 4, 4, "hold_planar(x, P, nominal_zero, error_zero)")) {
        return NULL;
    }
    Py_ssize_t nominal[MAX_N], error[MAX_N];
    Py_ssize_t n_nominal = indices(args[2], nominal, "nominal_zero");
    Py_ssize_t n_error = n_nominal < 0 ? -1 : indices(args[3], error, "error_zero");
    if (n_error < 0) {
        return NULL;
    }
    Held held = {.count = 0};
    double *x = hold(&held, args[0], 1, -1, "x");
    Py_ssize_t nx = x == NULL ? -1 : last_items(&held);
    double *P = nx < 0 ? NULL : hold(&held, args[1], 1, -1, "P");
    Py_ssize_t n = P == NULL ? -1 : square_side(last_items(&held), 6, "P");
    if (n < 0) {
        release(&held);
        return NULL;
    }
    if (nx < 7) {
        PyErr_SetString(PyExc_ValueError, "x must hold a pose");
        release(&held);
        return NULL;
    }
    if (!within(nominal, n_nominal, nx, "nominal_zero outside x") || !within(error, n_error, n, "error_zero outside P")) {
        release(&held);
        return NULL;
    }
    double qx = x[3], qy = x[4], qz = x[5], qw = x[6];
    if (qx != 0.0 || qy != 0.0) {
        double half = 0.5 * atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz));
        x[3] = 0.0, x[4] = 0.0, x[5] = sin(half), x[6] = cos(half);
    }
    for (Py_ssize_t k = 0; k < n_nominal; k++) {
        x[nominal[k]] = 0.0;
    }
    for (Py_ssize_t k = 0; k < n_error; k++) {
        Py_ssize_t r = error[k];
        memset(P + r * n, 0, sizeof(double) * (size_t)n);
        for (Py_ssize_t i = 0; i < n; i++) {
            P[i * n + r] = 0.0;
        }
    }
    release(&held);
    Py_RETURN_NONE;
}

/* -- snapshots -------------------------------------------------------------------------------- */

PyDoc_STRVAR(copy_into_doc,
"copy_into(x, P, x_to, P_to) -> None\n\n"
"x_to[...] = x and P_to[...] = P in one call (ErrorStateEKF.copy into a recycled snapshot): each pair\n"
"must be float64 C-contiguous of the same size, checked before anything is written (a ValueError\n"
"otherwise: the caller allocates a new snapshot).");

static PyObject *copy_into(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 4, 4, "copy_into(x, P, x_to, P_to)")) {
        return NULL;
    }
    Held held = {.count = 0};
    const double *x = hold(&held, args[0], 0, -1, "x");
    Py_ssize_t nx = x == NULL ? -1 : last_items(&held);
    const double *P = nx < 0 ? NULL : hold(&held, args[1], 0, -1, "P");
    Py_ssize_t nP = P == NULL ? -1 : last_items(&held);
    double *x_to = NULL, *P_to = NULL;
    if (nP < 0 || (x_to = hold(&held, args[2], 1, nx, "x_to")) == NULL ||
        (P_to = hold(&held, args[3], 1, nP, "P_to")) == NULL) {
        release(&held);
        return NULL;
    }
    memmove(x_to, x, sizeof(double) * (size_t)nx);
    memmove(P_to, P, sizeof(double) * (size_t)nP);
    release(&held);
    Py_RETURN_NONE;
}

/* -- the product propagate and update share ---------------------------------------------------- */

/* out = A P for A (rows x n) and P (n x n), row by row, skipping A's zeros: the motion model's F and
 * a measurement's H are mostly zeros, so this costs about their non-zeros times n. */
static void sparse_times(const double *A, Py_ssize_t rows, const double *P, Py_ssize_t n, double *out) {
    for (Py_ssize_t i = 0; i < rows; i++) {
        double *row = out + i * n;
        memset(row, 0, (size_t)n * sizeof(double));
        for (Py_ssize_t k = 0; k < n; k++) {
            double a = A[i * n + k];
            if (a == 0.0) {
                continue;
            }
            const double *pk = P + k * n;
            for (Py_ssize_t j = 0; j < n; j++) {
                row[j] += a * pk[j];
            }
        }
    }
}

/* -- propagate ------------------------------------------------------------------------------- */

PyDoc_STRVAR(propagate_doc,
"propagate(F, P, Q, out) -> bool\n\n"
"out = F P F^T + Q for n x n float64 arrays (out must not be P); True iff its diagonal is finite.");

static PyObject *propagate(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 4, 4, "propagate(F, P, Q, out)")) {
        return NULL;
    }
    Held held = {.count = 0};
    const double *F = NULL, *Q = NULL;
    double *out = NULL;
    const double *P = hold(&held, args[1], 0, -1, "P");
    Py_ssize_t n = P == NULL ? -1 : square_side(last_items(&held), 1, "P");
    if (n < 0 || (F = hold(&held, args[0], 0, n * n, "F")) == NULL || (Q = hold(&held, args[2], 0, n * n, "Q")) == NULL ||
        (out = hold(&held, args[3], 1, n * n, "out")) == NULL) {
        release(&held);
        return NULL;
    }
    double FP[MAX_N * MAX_N];
    sparse_times(F, n, P, n, FP); /* F is the identity but for a few blocks */
    /* out = FP F^T + Q: out_ij = sum_k FP_ik F_jk over F's non-zeros in row j (found once: about
     * n + 20 of them, so this costs n (n + 20) products instead of n^3), added in ascending k as the
     * dense sum does; a skipped term is FP_ik * 0, which adds nothing to a finite sum, and a
     * non-finite P reaches the trace through F's diagonal, which is never zero. */
    int nz_start[MAX_N + 1];
    int nz_col[MAX_N * MAX_N];
    double nz_val[MAX_N * MAX_N];
    int count = 0;
    for (Py_ssize_t j = 0; j < n; j++) {
        nz_start[j] = count;
        const double *fj = F + j * n;
        for (Py_ssize_t k = 0; k < n; k++) {
            if (fj[k] != 0.0) {
                nz_col[count] = (int)k, nz_val[count] = fj[k], count++;
            }
        }
    }
    nz_start[n] = count;
    double trace = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        const double *fpi = FP + i * n;
        for (Py_ssize_t j = 0; j < n; j++) {
            double acc = 0.0;
            for (int e = nz_start[j]; e < nz_start[j + 1]; e++) {
                acc += fpi[nz_col[e]] * nz_val[e];
            }
            out[i * n + j] = acc + Q[i * n + j];
        }
        trace += out[i * n + i];
    }
    release(&held);
    return PyBool_FromLong(isfinite(trace));
}

/* -- update ---------------------------------------------------------------------------------- */

PyDoc_STRVAR(update_doc,
"update(P, H, R, y, threshold2, keep, joseph, out, x, boxplus) -> (status, nis, innovation_var)\n\n"
"The Kalman update of ErrorStateEKF.update: P (n x n), H (m x n), R (m x m), y (m). threshold2 is\n"
"the squared Mahalanobis gate; keep (n) and joseph (n x n) the mask's weights, or None. P - K S K^T\n"
"is written into out; x (the nominal state) is moved by dx in place when boxplus is 1 (2: also\n"
"holding the heading), and dx itself written into x when boxplus is 0. status: 0 applied with a\n"
"non-negative finite diagonal, 1 gated, 2 S not positive definite (or NIS not finite), 3 applied\n"
"but the diagonal needs ekf.py's checks. innovation_var is the diagonal of S as a list.");

static PyObject *update(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 10, 10, "update")) {
        return NULL;
    }
    double threshold2 = PyFloat_AsDouble(args[4]);
    long mode = PyLong_AsLong(args[9]);
    if ((threshold2 == -1.0 || mode == -1) && PyErr_Occurred()) {
        return NULL;
    }
    int masked = args[5] != Py_None;
    Held held = {.count = 0};
    PyObject *result = NULL, *s_diag = NULL;
    const double *P, *H = NULL, *R = NULL, *y = NULL, *keep = NULL, *J = NULL;
    double *out = NULL, *x = NULL;
    Py_ssize_t n = -1, m = 0;
    if ((P = hold(&held, args[0], 0, -1, "P")) != NULL) {
        n = square_side(last_items(&held), 1, "P");
    }
    if (n < 0 || (y = hold(&held, args[3], 0, -1, "y")) == NULL) {
        goto done;
    }
    m = last_items(&held);
    if (m < 1 || m > MAX_M) {
        PyErr_Format(PyExc_ValueError, "y must have 1 to %d rows", MAX_M);
        goto done;
    }
    if ((H = hold(&held, args[1], 0, m * n, "H")) == NULL || (R = hold(&held, args[2], 0, m * m, "R")) == NULL ||
        (masked && ((keep = hold(&held, args[5], 0, n, "keep")) == NULL ||
                    (J = hold(&held, args[6], 0, n * n, "joseph")) == NULL)) ||
        (out = hold(&held, args[7], 1, n * n, "out")) == NULL ||
        (x = hold(&held, args[8], 1, mode == 0 ? n : n + 1, "x")) == NULL) {
        goto done;
    }
    {
        double HP[MAX_M * MAX_N], S[MAX_M * MAX_M], L[MAX_M * MAX_M], Li[MAX_M * MAX_M];
        double z[MAX_M], v[MAX_M], W[MAX_M * MAX_N], dx[MAX_N];

        sparse_times(H, m, P, n, HP); /* H touches a few columns */
        /* S = HP H^T + R */
        for (Py_ssize_t a = 0; a < m; a++) {
            for (Py_ssize_t b = 0; b < m; b++) {
                double acc = 0.0;
                for (Py_ssize_t k = 0; k < n; k++) {
                    acc += HP[a * n + k] * H[b * n + k];
                }
                S[a * m + b] = acc + R[a * m + b];
            }
        }
        s_diag = PyList_New(m);
        if (s_diag == NULL) {
            goto done;
        }
        for (Py_ssize_t a = 0; a < m; a++) {
            PyObject *f = PyFloat_FromDouble(S[a * m + a]);
            if (f == NULL) {
                goto done;
            }
            PyList_SET_ITEM(s_diag, a, f);
        }
        /* Cholesky S = L L^T (cholesky.factor: the lower triangle, row by row) */
        int status = APPLIED;
        memset(L, 0, sizeof(double) * (size_t)(m * m));
        for (Py_ssize_t i = 0; i < m && status == APPLIED; i++) {
            for (Py_ssize_t j = 0; j <= i; j++) {
                double acc = S[i * m + j];
                for (Py_ssize_t k = 0; k < j; k++) {
                    acc -= L[i * m + k] * L[j * m + k];
                }
                if (i == j) {
                    if (!(acc > 0.0) || !isfinite(acc)) {
                        status = SINGULAR;
                        break;
                    }
                    L[i * m + i] = sqrt(acc);
                } else {
                    L[i * m + j] = acc / L[j * m + j];
                }
            }
        }
        double nis = NAN;
        if (status == APPLIED) {
            /* L^-1 by forward substitution (cholesky.inverse_lower; for 2 x 2 its closed form,
             * cholesky._inverse_factor_2x2), z = L^-1 y, NIS = z.z */
            memset(Li, 0, sizeof(double) * (size_t)(m * m));
            if (m == 2) {
                Li[0] = 1.0 / L[0];
                Li[3] = 1.0 / L[3];
                Li[2] = -L[2] * Li[0] * Li[3];
            } else {
                for (Py_ssize_t c = 0; c < m; c++) {
                    for (Py_ssize_t i = c; i < m; i++) {
                        double acc = (i == c) ? 1.0 : 0.0;
                        for (Py_ssize_t k = c; k < i; k++) {
                            acc -= L[i * m + k] * Li[k * m + c];
                        }
                        Li[i * m + c] = acc / L[i * m + i];
                    }
                }
            }
            nis = 0.0;
            for (Py_ssize_t i = 0; i < m; i++) {
                double acc = Li[i * m] * y[0];
                for (Py_ssize_t k = 1; k <= i; k++) {
                    acc += Li[i * m + k] * y[k];
                }
                z[i] = acc;
                nis += acc * acc;
            }
            if (!isfinite(nis)) {
                status = SINGULAR;
            } else if (nis > threshold2) {
                status = GATED;
            }
        }
        if (status == APPLIED) {
            /* v = L^-T z; dx = HP^T v (= K y); W = L^-1 HP */
            for (Py_ssize_t j = 0; j < m; j++) {
                double acc = z[j] * Li[j * m + j];
                for (Py_ssize_t i = j + 1; i < m; i++) {
                    acc += z[i] * Li[i * m + j];
                }
                v[j] = acc;
            }
            for (Py_ssize_t k = 0; k < n; k++) {
                double acc = 0.0;
                for (Py_ssize_t a = 0; a < m; a++) {
                    acc += v[a] * HP[a * n + k];
                }
                dx[k] = acc;
            }
            for (Py_ssize_t a = 0; a < m; a++) {
                for (Py_ssize_t k = 0; k < n; k++) {
                    double acc = 0.0;
                    for (Py_ssize_t b = 0; b <= a; b++) {
                        acc += Li[a * m + b] * HP[b * n + k];
                    }
                    W[a * n + k] = acc;
                }
            }
            /* out = P - (W^T W) .* J, its diagonal checked as it is written */
            int diagonal_ok = 1;
            for (Py_ssize_t i = 0; i < n; i++) {
                for (Py_ssize_t j = 0; j < n; j++) {
                    double c = 0.0;
                    for (Py_ssize_t a = 0; a < m; a++) {
                        c += W[a * n + i] * W[a * n + j];
                    }
                    if (J != NULL) {
                        c *= J[i * n + j];
                    }
                    out[i * n + j] = P[i * n + j] - c;
                }
                double d = out[i * n + i];
                if (!(d >= 0.0) || !isfinite(d)) {
                    diagonal_ok = 0;
                }
            }
            if (keep != NULL) {
                for (Py_ssize_t k = 0; k < n; k++) {
                    dx[k] *= keep[k];
                }
            }
            if (mode == 0) {
                memcpy(x, dx, sizeof(double) * (size_t)n);
            } else if (boxplus(x, n + 1, dx, mode == 2) < 0) {
                PyErr_SetString(PyExc_ArithmeticError, "quaternion has zero or non-finite norm");
                goto done;
            }
            if (!diagonal_ok) {
                status = NEEDS_CHECK;
            }
        }
        result = Py_BuildValue("(idO)", status, nis, s_diag);
    }
done:
    Py_XDECREF(s_diag);
    release(&held);
    return result;
}

/* -- the smoother's fold (smoother.py OpenSegment._fold, backend.rts_fold) ---------------------- */

/* out = A P0 F^T P1^-1 on the components P1 gives any variance (idx: P1_ii > 0; a component held at an
 * exact value has no smoothing gain, out's column 0): C = F P0, S = P1[idx, idx] = L L^T, X = S^-1 C[idx],
 * out[:, idx] = A X^T. 0, with nothing written, when S is not positive definite (the reference's least
 * squares takes it). The same maths as rts.rts_gain, one call instead of a dozen numpy ones. */
static int fold_into(Py_ssize_t n, const double *A, const double *P0, const double *F, const double *P1,
                     double *out) {
    double C[MAX_N * MAX_N], L[MAX_N * MAX_N], X[MAX_N * MAX_N];
    Py_ssize_t idx[MAX_N], k = 0;
    for (Py_ssize_t i = 0; i < n; i++) {
        if (P1[i * n + i] > 0.0) {
            idx[k++] = i;
        }
    }
    sparse_times(F, n, P0, n, C);
    for (Py_ssize_t i = 0; i < k; i++) { /* S = L L^T, L's lower triangle */
        for (Py_ssize_t j = 0; j <= i; j++) {
            double s = P1[idx[i] * n + idx[j]];
            for (Py_ssize_t m = 0; m < j; m++) {
                s -= L[i * k + m] * L[j * k + m];
            }
            if (i == j) {
                if (!(s > 0.0)) {
                    return 0;
                }
                L[i * k + i] = sqrt(s);
            } else {
                L[i * k + j] = s / L[j * k + j];
            }
        }
    }
    for (Py_ssize_t i = 0; i < k; i++) { /* L Y = C[idx] */
        double *x = X + i * n;
        memcpy(x, C + idx[i] * n, (size_t)n * sizeof(double));
        for (Py_ssize_t m = 0; m < i; m++) {
            const double v = L[i * k + m], *y = X + m * n;
            for (Py_ssize_t j = 0; j < n; j++) {
                x[j] -= v * y[j];
            }
        }
        for (Py_ssize_t j = 0; j < n; j++) {
            x[j] /= L[i * k + i];
        }
    }
    for (Py_ssize_t i = k - 1; i >= 0; i--) { /* L^T X = Y */
        double *x = X + i * n;
        for (Py_ssize_t m = i + 1; m < k; m++) {
            const double v = L[m * k + i], *y = X + m * n;
            for (Py_ssize_t j = 0; j < n; j++) {
                x[j] -= v * y[j];
            }
        }
        for (Py_ssize_t j = 0; j < n; j++) {
            x[j] /= L[i * k + i];
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) { /* out = A G, G[:, idx[r]] = X[r]^T */
        const double *a = A + i * n;
        double *o = out + i * n;
        memset(o, 0, (size_t)n * sizeof(double));
        for (Py_ssize_t r = 0; r < k; r++) {
            const double *x = X + r * n;
            double s = 0.0;
            for (Py_ssize_t l = 0; l < n; l++) {
                s += a[l] * x[l];
            }
            o[idx[r]] = s;
        }
    }
    return 1;
}

static PyObject *rts_fold(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 5, 5, "rts_fold(A, P0, F, P1, out)")) {
        return NULL;
    }
    Held held = {.count = 0};
    const double *A = hold(&held, args[0], 0, -1, "A");
    Py_ssize_t n = A == NULL ? -1 : square_side(last_items(&held), 1, "A");
    const double *P0 = NULL, *F = NULL, *P1 = NULL;
    double *out = NULL;
    if (n < 0 || (P0 = hold(&held, args[1], 0, n * n, "P0")) == NULL ||
        (F = hold(&held, args[2], 0, n * n, "F")) == NULL || (P1 = hold(&held, args[3], 0, n * n, "P1")) == NULL ||
        (out = hold(&held, args[4], 1, n * n, "out")) == NULL) {
        release(&held);
        return NULL;
    }
    int ok = fold_into(n, A, P0, F, P1, out);
    release(&held);
    return PyBool_FromLong(ok);
}

PyDoc_STRVAR(rts_fold_doc, "rts_fold(A, P0, F, P1, out) -> bool: out = A P0 F^T P1^-1 on the components of P1 "
                           "with variance; False (out untouched) when that block of P1 is not positive definite.");

/* -- the odometry's forward acceleration --------------------------------------------------------- */

PyDoc_STRVAR(line_fit_doc,
"line_fit(pairs) -> (slope, misfit) or None\n\n"
"line_fit.line_fit of a tuple of (t, v) tuples of floats: the same sums in the same order, the squares\n"
"by libm's pow as Python's ** takes them, so the same doubles. None when an item is not a 2-tuple of\n"
"floats, there are fewer than three, or the t are all one (the reference decides those).");

/* libm's pow through a pointer the compiler cannot see through: it would otherwise turn pow(d, 2.0) into
 * d * d, which Python's d ** 2 (float_pow: pow of |d|) is not guaranteed to equal. */
static double (*volatile libm_pow)(double, double) = pow;

static int pair_of(PyObject *item, double *t, double *v) {
    if (!PyTuple_CheckExact(item) || PyTuple_GET_SIZE(item) != 2) {
        return 0;
    }
    PyObject *a = PyTuple_GET_ITEM(item, 0), *b = PyTuple_GET_ITEM(item, 1);
    if (!PyFloat_CheckExact(a) || !PyFloat_CheckExact(b)) {
        return 0;
    }
    *t = PyFloat_AS_DOUBLE(a);
    *v = PyFloat_AS_DOUBLE(b);
    return 1;
}

static PyObject *line_fit(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 1, 1, "line_fit(pairs)")) {
        return NULL;
    }
    PyObject *pairs = args[0];
    if (!PyTuple_CheckExact(pairs) || PyTuple_GET_SIZE(pairs) < 3) {
        Py_RETURN_NONE;
    }
    Py_ssize_t n = PyTuple_GET_SIZE(pairs);
    double t, v, st = 0.0, sv = 0.0;  /* Python's sum: 0 + the first item, then each in turn */
    for (Py_ssize_t i = 0; i < n; i++) {
        if (!pair_of(PyTuple_GET_ITEM(pairs, i), &t, &v)) {
            Py_RETURN_NONE;
        }
        st += t;
        sv += v;
    }
    double tm = st / (double)n, vm = sv / (double)n;
    double stt = 0.0, stv = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        pair_of(PyTuple_GET_ITEM(pairs, i), &t, &v);
        double d = t - tm, dv = v - vm;
        stt += libm_pow(fabs(d), 2.0);
        stv += d * dv;
    }
    if (stt == 0.0) {
        Py_RETURN_NONE;
    }
    double slope = stv / stt, srr = 0.0;
    for (Py_ssize_t i = 0; i < n; i++) {
        pair_of(PyTuple_GET_ITEM(pairs, i), &t, &v);
        double d = t - tm, dv = v - vm;
        double r = dv - slope * d;
        srr += libm_pow(fabs(r), 2.0);
    }
    return Py_BuildValue("(dd)", slope, sqrt(srr / (double)(n - 2)));
}


/* -- zero motion (zero_motion.py) ----------------------------------------------------------------- */

PyDoc_STRVAR(difference_noise_doc,
"difference_noise(track, values, stamp, period, gap_factor, memory) -> tuple or None\n\n"
"zero_motion.difference_noise to the bit; None where it would not be plain floats in tuples, or a square\n"
"overflows (the reference decides those).");

/* Six floats of a tuple; 0 when it is not a 6-tuple of exact floats. */
static int six_floats(PyObject *obj, double *out) {
    if (!PyTuple_CheckExact(obj) || PyTuple_GET_SIZE(obj) != 6) {
        return 0;
    }
    for (Py_ssize_t i = 0; i < 6; i++) {
        PyObject *item = PyTuple_GET_ITEM(obj, i);
        if (!PyFloat_CheckExact(item)) {
            return 0;
        }
        out[i] = PyFloat_AS_DOUBLE(item);
    }
    return 1;
}

/* A tuple of the given items, each a new reference stolen (NULL: an error is set and the rest released). */
static PyObject *tuple_of(Py_ssize_t n, PyObject **items) {
    PyObject *t = PyTuple_New(n);
    for (Py_ssize_t i = 0; i < n; i++) {
        if (t == NULL || items[i] == NULL) {
            for (Py_ssize_t j = i; j < n; j++) {
                Py_XDECREF(items[j]);
            }
            Py_XDECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, items[i]);
    }
    return t;
}

static PyObject *float_tuple(const double *v, Py_ssize_t n) {
    PyObject *items[6];
    for (Py_ssize_t i = 0; i < n; i++) {
        items[i] = PyFloat_FromDouble(v[i]);
    }
    return tuple_of(n, items);
}

static PyObject *difference_noise(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 6, 6, "difference_noise(track, values, stamp, period, gap_factor, memory)")) {
        return NULL;
    }
    PyObject *track = args[0], *values = args[1], *stamp = args[2];
    double a[6], b[6], var[6];
    if (!six_floats(values, a) || !PyFloat_CheckExact(stamp) || !PyFloat_CheckExact(args[3]) ||
        !PyFloat_CheckExact(args[4]) || !PyFloat_CheckExact(args[5])) {
        Py_RETURN_NONE;
    }
    if (track == Py_None) {
        Py_INCREF(values), Py_INCREF(Py_None), Py_INCREF(stamp);
        PyObject *items[4] = {values, Py_None, PyFloat_FromDouble(0.0), stamp};
        return tuple_of(4, items);
    }
    if (!PyTuple_CheckExact(track) || PyTuple_GET_SIZE(track) != 4) {
        Py_RETURN_NONE;
    }
    PyObject *var_obj = PyTuple_GET_ITEM(track, 1), *weight_obj = PyTuple_GET_ITEM(track, 2);
    PyObject *last = PyTuple_GET_ITEM(track, 3);
    int has_var = var_obj != Py_None;
    if (!six_floats(PyTuple_GET_ITEM(track, 0), b) || (has_var && !six_floats(var_obj, var)) ||
        !PyFloat_CheckExact(weight_obj) || !PyFloat_CheckExact(last)) {
        Py_RETURN_NONE;
    }
    double t = PyFloat_AS_DOUBLE(stamp), period = PyFloat_AS_DOUBLE(args[3]);
    double gap_factor = PyFloat_AS_DOUBLE(args[4]), memory = PyFloat_AS_DOUBLE(args[5]);
    if (period > 0.0 && t - PyFloat_AS_DOUBLE(last) > gap_factor * period) {
        Py_INCREF(values), Py_INCREF(var_obj), Py_INCREF(weight_obj), Py_INCREF(stamp);
        PyObject *items[4] = {values, var_obj, weight_obj, stamp};
        return tuple_of(4, items);
    }
    double weight = PyFloat_AS_DOUBLE(weight_obj);
    weight = weight < memory ? weight + 1.0 : memory;
    double d[6];
    for (int i = 0; i < 6; i++) {
        double sq = libm_pow(fabs(a[i] - b[i]), 2.0);
        if (!isfinite(sq) && isfinite(a[i] - b[i])) {
            Py_RETURN_NONE; /* Python's ** raises OverflowError there */
        }
        d[i] = 0.5 * sq;
    }
    if (has_var) {
        double g = 1.0 / weight;
        for (int i = 0; i < 6; i++) {
            d[i] = var[i] + g * (d[i] - var[i]);
        }
    }
    Py_INCREF(values), Py_INCREF(stamp);
    PyObject *items[4] = {values, float_tuple(d, 6), PyFloat_FromDouble(weight), stamp};
    return tuple_of(4, items);
}

PyDoc_STRVAR(zero_mean_window_doc,
"zero_mean_window(window, values, measured, running, stamp, span, z, min_window, floor, bound) -> (window, bool)\n"
"or None\n\n"
"zero_motion.zero_mean_window to the bit; None where its items are not the plain floats, bools and tuples\n"
"it takes, or a square overflows (the reference decides those). bound(n) is called as the reference does.");

static PyObject *zero_mean_window(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (!takes(nargs, 10, 10, "zero_mean_window(window, values, measured, running, stamp, span, z, min_window, "
                              "floor, bound)")) {
        return NULL;
    }
    PyObject *window = args[0], *values = args[1], *measured = args[2], *running = args[3], *stamp = args[4];
    double v[6], var[6];
    int used[6];
    if (!PyTuple_CheckExact(window) || !six_floats(values, v) || !PyTuple_CheckExact(measured) ||
        PyTuple_GET_SIZE(measured) != 6 || !PyFloat_CheckExact(stamp) || !PyFloat_CheckExact(args[5]) ||
        !PyFloat_CheckExact(args[6]) || !PyLong_CheckExact(args[7]) || !PyFloat_CheckExact(args[8]) ||
        (running != Py_None && !six_floats(running, var))) {
        Py_RETURN_NONE;
    }
    for (int i = 0; i < 6; i++) {
        PyObject *m = PyTuple_GET_ITEM(measured, i);
        if (m != Py_True && m != Py_False) {
            Py_RETURN_NONE;
        }
        used[i] = m == Py_True;
    }
    double t = PyFloat_AS_DOUBLE(stamp), span = PyFloat_AS_DOUBLE(args[5]), z = PyFloat_AS_DOUBLE(args[6]);
    double floor_var = PyFloat_AS_DOUBLE(args[8]);
    Py_ssize_t min_window = PyLong_AsSsize_t(args[7]);
    if (min_window < 1) {
        Py_RETURN_NONE;
    }
    double zz = z * z;
    if (running != Py_None) {
        for (int i = 0; i < 6; i++) {
            if (used[i] && v[i] * v[i] > zz * (var[i] > floor_var ? var[i] : floor_var)) {
                return Py_BuildValue("(()O)", Py_False); /* moving */
            }
        }
    }
    Py_ssize_t len = PyTuple_GET_SIZE(window), n = len + 1, drop = 0;
    /* every entry a (float stamp, six floats) pair, checked before any is read */
    for (Py_ssize_t e = 0; e < len; e++) {
        PyObject *entry = PyTuple_GET_ITEM(window, e);
        double unused[6];
        if (!PyTuple_CheckExact(entry) || PyTuple_GET_SIZE(entry) != 2 ||
            !PyFloat_CheckExact(PyTuple_GET_ITEM(entry, 0)) || !six_floats(PyTuple_GET_ITEM(entry, 1), unused)) {
            Py_RETURN_NONE;
        }
    }
    while (n - drop > min_window && t - PyFloat_AS_DOUBLE(PyTuple_GET_ITEM(PyTuple_GET_ITEM(window, drop), 0)) >= span) {
        drop++;
    }
    n = len - drop + 1;
    PyObject *kept = PyTuple_New(n);
    if (kept == NULL) {
        return NULL;
    }
    for (Py_ssize_t e = drop; e < len; e++) {
        PyObject *entry = PyTuple_GET_ITEM(window, e);
        Py_INCREF(entry);
        PyTuple_SET_ITEM(kept, e - drop, entry);
    }
    Py_INCREF(stamp), Py_INCREF(values);
    PyObject *pair_items[2] = {stamp, values};
    PyObject *pair = tuple_of(2, pair_items);
    if (pair == NULL) {
        Py_DECREF(kept);
        return NULL;
    }
    PyTuple_SET_ITEM(kept, n - 1, pair);
    if (n < min_window) {
        return Py_BuildValue("(NO)", kept, Py_False);
    }
    if (n < 2) { /* no difference to measure a noise from: the reference raises ZeroDivisionError */
        Py_DECREF(kept);
        Py_RETURN_NONE;
    }
    PyObject *n_obj = PyLong_FromSsize_t(n);
    PyObject *b_obj = n_obj == NULL ? NULL : PyObject_CallOneArg(args[9], n_obj);
    Py_XDECREF(n_obj);
    if (b_obj == NULL) {
        Py_DECREF(kept);
        return NULL;
    }
    double b = PyFloat_AsDouble(b_obj);
    Py_DECREF(b_obj);
    if (b == -1.0 && PyErr_Occurred()) {
        Py_DECREF(kept);
        return NULL;
    }
    for (int i = 0; i < 6; i++) {
        if (!used[i]) {
            continue;
        }
        double total = 0.0, diff2 = 0.0, previous = 0.0;
        for (Py_ssize_t e = 0; e < n; e++) {
            double x = PyFloat_AS_DOUBLE(PyTuple_GET_ITEM(PyTuple_GET_ITEM(PyTuple_GET_ITEM(kept, e), 1), i));
            total += x;
            if (e > 0) {
                double sq = libm_pow(fabs(x - previous), 2.0);
                if (!isfinite(sq) && isfinite(x - previous)) {
                    Py_DECREF(kept);
                    Py_RETURN_NONE; /* Python's ** raises OverflowError there */
                }
                diff2 += sq;
            }
            previous = x;
        }
        double s2 = diff2 / (2.0 * (double)(n - 1));
        if (total * total / (double)n > b * (s2 > floor_var ? s2 : floor_var)) {
            return Py_BuildValue("(NO)", kept, Py_False);
        }
    }
    return Py_BuildValue("(NO)", kept, Py_True);
}

static PyMethodDef methods[] = {
    {"propagate", (PyCFunction)(void (*)(void))propagate, METH_FASTCALL, propagate_doc},
    {"update", (PyCFunction)(void (*)(void))update, METH_FASTCALL, update_doc},
    {"predict", (PyCFunction)(void (*)(void))predict, METH_FASTCALL, predict_doc},
    {"orientation", (PyCFunction)(void (*)(void))orientation, METH_FASTCALL, orientation_doc},
    {"copy_into", (PyCFunction)(void (*)(void))copy_into, METH_FASTCALL, copy_into_doc},
    {"add_motion_noise", (PyCFunction)(void (*)(void))add_motion_noise, METH_FASTCALL, add_motion_noise_doc},
    {"hold_planar", (PyCFunction)(void (*)(void))hold_planar, METH_FASTCALL, hold_planar_doc},
    {"rts_fold", (PyCFunction)(void (*)(void))rts_fold, METH_FASTCALL, rts_fold_doc},
    {"line_fit", (PyCFunction)(void (*)(void))line_fit, METH_FASTCALL, line_fit_doc},
    {"difference_noise", (PyCFunction)(void (*)(void))difference_noise, METH_FASTCALL, difference_noise_doc},
    {"zero_mean_window", (PyCFunction)(void (*)(void))zero_mean_window, METH_FASTCALL, zero_mean_window_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "The error-state EKF's fixed-size linear algebra in C (see the source's header).", -1, methods,
    NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__kernels(void) {
    PyObject *mod = PyModule_Create(&module);
    if (mod == NULL) {
        return NULL;
    }
    if (PyModule_AddIntConstant(mod, "MAX_N", MAX_N) < 0 || PyModule_AddIntConstant(mod, "MAX_M", MAX_M) < 0 ||
        PyModule_AddIntConstant(mod, "APPLIED", APPLIED) < 0 || PyModule_AddIntConstant(mod, "GATED", GATED) < 0 ||
        PyModule_AddIntConstant(mod, "SINGULAR", SINGULAR) < 0 ||
        PyModule_AddIntConstant(mod, "NEEDS_CHECK", NEEDS_CHECK) < 0 ||
        PyModule_AddIntConstant(mod, "BLOCK_GYRO_BIAS", BLOCK_GYRO_BIAS) < 0 ||
        PyModule_AddIntConstant(mod, "BLOCK_WHEEL_SCALE", BLOCK_WHEEL_SCALE) < 0 ||
        PyModule_AddIntConstant(mod, "BLOCK_GYRO_SCALE", BLOCK_GYRO_SCALE) < 0 ||
        PyModule_AddIntConstant(mod, "BLOCK_TWIST_PITCH", BLOCK_TWIST_PITCH) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
