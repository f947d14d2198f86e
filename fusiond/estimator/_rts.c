/*
 * fusiond.estimator._rts: the smoother's one per-step kernel, compiled.
 *
 * The recorder folds each run of the filter's transitions into the composed RTS map
 * (smoother.py, OpenSegment._fold): A <- A G with G = P0 F^T P1^-1 on the components P1 gives any
 * variance (a component held at an exact value has no smoothing gain). At the 9-16 dimensional
 * states fusiond runs, numpy's and LAPACK's call overheads (the product, the indexing of the held
 * components, the Cholesky solve) were ~30 us a fold against ~2 us of arithmetic, paid once per
 * correction and per output moment. This is the same maths in one call; the Python in
 * smoother.py (rts_gain) is the reference, held equal to this by tests/unit/test_smoother.py, and
 * the path taken where this module was not built.
 *
 *   fold(A, P0, F, P1, out): C = F P0; idx = {i : P1_ii > 0}; S = P1[idx, idx] = L L^T (Cholesky);
 *   X = S^-1 C[idx, :]; out[:, idx] = A[:, :] X^T, out's other columns 0. Returns False, with
 *   nothing written, when S is not positive definite (the caller's least-squares path takes it).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

#define MAX_N 48 /* the error dimension handled here, as _kernels.c's */

/* A C-contiguous float64 buffer of exactly `count` items; a BufferError or ValueError otherwise. */
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

/* The fold's arithmetic (module doc); 1 when done, 0 when S is not positive definite. */
static int fold_into(int n, const double *A, const double *P0, const double *F, const double *P1, double *out) {
    double C[MAX_N * MAX_N], L[MAX_N * MAX_N], X[MAX_N * MAX_N];
    int idx[MAX_N];
    int k = 0;
    for (int i = 0; i < n; i++)
        if (P1[i * n + i] > 0.0) idx[k++] = i;
    /* C = F P0, only the rows idx are needed */
    for (int r = 0; r < k; r++) {
        const double *f = F + idx[r] * n;
        double *c = C + r * n;
        for (int j = 0; j < n; j++) c[j] = 0.0;
        for (int l = 0; l < n; l++) {
            double v = f[l];
            if (v == 0.0) continue;
            const double *p = P0 + l * n;
            for (int j = 0; j < n; j++) c[j] += v * p[j];
        }
    }
    /* S = L L^T, lower triangle of L */
    for (int i = 0; i < k; i++) {
        for (int j = 0; j <= i; j++) {
            double s = P1[idx[i] * n + idx[j]];
            for (int m = 0; m < j; m++) s -= L[i * k + m] * L[j * k + m];
            if (i == j) {
                if (!(s > 0.0)) return 0;
                L[i * k + i] = sqrt(s);
            } else {
                L[i * k + j] = s / L[j * k + j];
            }
        }
    }
    /* X = S^-1 C: L Y = C, then L^T X = Y, column by column of C (all n at once per row) */
    for (int i = 0; i < k; i++) {
        double *x = X + i * n;
        memcpy(x, C + i * n, n * sizeof(double));
        for (int m = 0; m < i; m++) {
            double v = L[i * k + m];
            const double *y = X + m * n;
            for (int j = 0; j < n; j++) x[j] -= v * y[j];
        }
        double d = L[i * k + i];
        for (int j = 0; j < n; j++) x[j] /= d;
    }
    for (int i = k - 1; i >= 0; i--) {
        double *x = X + i * n;
        for (int m = i + 1; m < k; m++) {
            double v = L[m * k + i];
            const double *y = X + m * n;
            for (int j = 0; j < n; j++) x[j] -= v * y[j];
        }
        double d = L[i * k + i];
        for (int j = 0; j < n; j++) x[j] /= d;
    }
    /* out = A G, G[:, idx[r]] = X[r, :]^T */
    for (int i = 0; i < n; i++) {
        const double *a = A + i * n;
        double *o = out + i * n;
        for (int j = 0; j < n; j++) o[j] = 0.0;
        for (int r = 0; r < k; r++) {
            const double *x = X + r * n;
            double s = 0.0;
            for (int l = 0; l < n; l++) s += a[l] * x[l];
            o[idx[r]] = s;
        }
    }
    return 1;
}

static PyObject *fold(PyObject *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "fold(A, P0, F, P1, out) takes five arrays");
        return NULL;
    }
    Py_buffer v[5];
    int got = 0;
    PyObject *result = NULL;
    if (get_doubles(args[0], &v[0], 0, -1, "A") < 0) return NULL;
    got = 1;
    Py_ssize_t nn = v[0].len / 8;
    int n = (int)sqrt((double)nn);
    if ((Py_ssize_t)n * n != nn || n > MAX_N || n < 1) {
        PyErr_Format(PyExc_ValueError, "A must be n x n with n <= %d, got %zd values", MAX_N, nn);
        goto done;
    }
    static const char *names[5] = {"A", "P0", "F", "P1", "out"};
    for (; got < 5; got++)
        if (get_doubles(args[got], &v[got], got == 4, nn, names[got]) < 0) goto done;
    int ok = fold_into(n, v[0].buf, v[1].buf, v[2].buf, v[3].buf, v[4].buf);
    result = PyBool_FromLong(ok);
done:
    for (int i = 0; i < got; i++) PyBuffer_Release(&v[i]);
    return result;
}

static PyMethodDef methods[] = {
    {"fold", (PyCFunction)(void (*)(void))fold, METH_FASTCALL,
     "fold(A, P0, F, P1, out) -> bool: out = A P0 F^T P1^-1 on P1's components with variance (module doc)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rts", "The smoother's fold, compiled.", -1, methods};

PyMODINIT_FUNC PyInit__rts(void) { return PyModule_Create(&module); }
