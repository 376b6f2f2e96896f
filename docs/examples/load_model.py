"""Load a model exported by ambid (.npz) and print its frequency response G(e^{j2πf·Ts}).

    python3 load_model.py models/oe8.npz 10 100 1000

Works on every export: polynomial models (ARX, OE, BJ, ...: `structure` is not "ss") carry the
polynomials A, B, C, D, F in ascending powers of q^-1, state-space models (`structure` "ss")
the matrices A, B, C, D (and K). Only numpy is needed.
"""
import sys

import numpy as np


def frequency_response(path, f_hz):
    """G(e^{j 2 pi f Ts}) of the input -> output part of the exported model at f_hz (Hz)."""
    z = np.load(path)  # plain arrays: no allow_pickle needed
    ts = float(z["Ts"])
    q_inv = np.exp(-2j * np.pi * np.asarray(f_hz, dtype=float) * ts)  # q^-1 on the unit circle
    if str(z["structure"]) == "ss":
        # x(k+1) = A x + B u, y = C x + D u  ->  G(z) = C (z I - A)^-1 B + D
        A, B, C, D = z["A"], z["B"], z["C"], z["D"]
        eye = np.eye(A.shape[0])
        return np.array([(C @ np.linalg.solve(eye / qi - A, B) + D)[0, 0] for qi in q_inv])
    # A(q) y = B(q)/F(q) u + C(q)/D(q) e  ->  G = B / (A F); np.polyval wants descending powers
    A, B, F = z["A"], z["B"], z["F"]

    def p(c):
        return np.polyval(c[::-1], q_inv)

    return p(B) / (p(A) * p(F))


def poles(path):
    """Poles of G in the z-plane: eigenvalues of A, or the roots of A F (in z)."""
    z = np.load(path)
    if str(z["structure"]) == "ss":
        return np.linalg.eigvals(z["A"])
    return np.roots(np.convolve(z["A"], z["F"]))


if __name__ == "__main__":
    path, f_hz = sys.argv[1], [float(f) for f in sys.argv[2:]]
    z = np.load(path)
    print(f"model {z['model_name']}: structure {z['structure']}, Ts = {float(z['Ts']):.6g} s")
    print(f"unstable poles: {int(np.sum(np.abs(poles(path)) >= 1.0))}")
    for f, g in zip(f_hz, frequency_response(path, f_hz)):
        print(f"G {f:.17g} {g.real:.17g} {g.imag:.17g}")
