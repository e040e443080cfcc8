#!/usr/bin/python3
"""The full array model's maximum likelihood as a Python user would write it with SciPy (issue 28,
item 4: calibd against "a straightforward numpy/scipy ML implementation").

Same problem and start as bench/array_full_ceres.cc (which writes them: `array_full_ceres_bench
export N FILE`): every dynamic sample's motion (omega, omega_dot, s) is an unknown, each static a
gravity direction (two angles), every triad its T_a, b_a, T_g, b_g and position; gauges as in the
Ceres bench (the reference triad's position and the lower triangle of its T_a held, the scale by
its T_g[0][0]), so the minimum cost is calibd's and Ceres'. Residuals vectorised in NumPy;
scipy.optimize.least_squares (trust region reflective, the default) with the Jacobian by finite
differences over the problem's sparsity pattern (jac_sparsity: SciPy groups the columns so one
Jacobian costs ~250 residual evaluations, not 20 000), x_scale="jac", tolerances 1e-10 as calibd's.

    python3 bench/array_full_scipy.py FILE

prints the iterations, the final cost (sum of squared whitened residuals, to compare with the
other two), process CPU seconds (all threads: NumPy's BLAS may use both cores) and peak RSS.
"""
import resource
import sys
import time

import numpy as np
import scipy.sparse as sp
from scipy.optimize import least_squares


def load(path):
    with open(path, "rb") as f:
        head = f.readline().split()
        data = np.frombuffer(f.read(), dtype="<f8")
    K, Nd, J, ref = (int(v) for v in head[:4])
    wa, wg, g = (float(v) for v in head[4:])
    sizes = [Nd * 3 * K, Nd * 3 * K, J * 3 * K, J * 3 * K, J, 9 * K, 3 * K, 9 * K, 3 * K, 3 * K,
             3 * J, 9 * Nd]
    assert data.size == sum(sizes), "file size does not match its header"
    parts = np.split(data, np.cumsum(sizes)[:-1])
    return dict(K=K, Nd=Nd, J=J, ref=ref, wa=wa, wg=wg, g=g,
                ya=parts[0].reshape(Nd, K, 3), yg=parts[1].reshape(Nd, K, 3),
                sa=parts[2].reshape(J, K, 3), sg=parts[3].reshape(J, K, 3), n=parts[4],
                Ta=parts[5].reshape(K, 3, 3), ba=parts[6].reshape(K, 3),
                Tg=parts[7].reshape(K, 3, 3), bg=parts[8].reshape(K, 3),
                r=parts[9].reshape(K, 3), sd=parts[10].reshape(J, 3), x=parts[11].reshape(Nd, 9))


class Model:
    """Unknowns z = [free triad parameters, 2 angles per static, 9 per dynamic sample]."""

    def __init__(self, p):
        self.p = p
        K, J, Nd, ref = p["K"], p["J"], p["Nd"], p["ref"]
        # Full triad vector per triad: T_a (9), b_a (3), T_g (9), b_g (3), r (3) = 27.
        self.held = np.zeros(27 * K, dtype=bool)
        self.held[27 * ref + np.array([3, 6, 7])] = True  # lower triangle of T_a,ref
        self.held[27 * ref + 12] = True  # T_g,ref[0][0]
        self.held[27 * ref + 24 + np.arange(3)] = True  # r_ref
        self.full0 = np.concatenate([np.concatenate([p["Ta"][k].ravel(), p["ba"][k],
                                                     p["Tg"][k].ravel(), p["bg"][k], p["r"][k]])
                                     for k in range(K)])
        self.free = np.flatnonzero(~self.held)
        self.ng = self.free.size
        sd = p["sd"] / np.linalg.norm(p["sd"], axis=1, keepdims=True)
        angles = np.stack([np.arctan2(sd[:, 1], sd[:, 0]), np.arcsin(sd[:, 2])], axis=1)
        self.z0 = np.concatenate([self.full0[self.free], angles.ravel(), p["x"].ravel()])
        self.w_static = np.sqrt(p["n"])[:, None, None]

    def unpack(self, z):
        p, K, J, Nd = self.p, self.p["K"], self.p["J"], self.p["Nd"]
        full = self.full0.copy()
        full[self.free] = z[:self.ng]
        t = full.reshape(K, 27)
        Ta, ba = t[:, 0:9].reshape(K, 3, 3), t[:, 9:12]
        Tg, bg, r = t[:, 12:21].reshape(K, 3, 3), t[:, 21:24], t[:, 24:27]
        ang = z[self.ng:self.ng + 2 * J].reshape(J, 2)
        s = np.stack([np.cos(ang[:, 1]) * np.cos(ang[:, 0]), np.cos(ang[:, 1]) * np.sin(ang[:, 0]),
                      np.sin(ang[:, 1])], axis=1)
        x = z[self.ng + 2 * J:].reshape(Nd, 9)
        return Ta, ba, Tg, bg, r, s, x

    def residuals(self, z):
        p = self.p
        Ta, ba, Tg, bg, r, s, x = self.unpack(z)
        om, omd, acc = x[:, None, 0:3], x[:, None, 3:6], x[:, None, 6:9]
        u = np.cross(om, np.cross(om, r[None])) + np.cross(omd, r[None]) + acc
        ra = p["wa"] * (p["ya"] - np.einsum("kij,nkj->nki", Ta, u) - ba[None])
        rg = p["wg"] * (p["yg"] - np.einsum("kij,nj->nki", Tg, x[:, 0:3]) - bg[None])
        rsa = p["wa"] * self.w_static * (p["sa"] - p["g"] * np.einsum("kij,sj->ski", Ta, s) - ba[None])
        rsg = p["wg"] * self.w_static * (p["sg"] - bg[None])
        return np.concatenate([ra.ravel(), rg.ravel(), rsa.ravel(), rsg.ravel()])

    def sparsity(self):
        """Which unknowns each residual depends on (rows in the order of residuals())."""
        p, K, J, Nd = self.p, self.p["K"], self.p["J"], self.p["Nd"]
        col_of_full = -np.ones(27 * K, dtype=np.int64)
        col_of_full[self.free] = np.arange(self.ng)
        rows, cols = [], []

        def add(row, full_cols):
            c = col_of_full[np.asarray(full_cols)]
            c = c[c >= 0]
            rows.extend([row] * c.size)
            cols.extend(c.tolist())

        ang0, x0 = self.ng, self.ng + 2 * J
        row = 0
        for kind in ("dyn_a", "dyn_g", "st_a", "st_g"):
            count = Nd if kind.startswith("dyn") else J
            for m in range(count):
                for k in range(K):
                    base = 27 * k
                    for i in range(3):
                        if kind == "dyn_a":
                            add(row, [base + 3 * i + j for j in range(3)] + [base + 9 + i]
                                + [base + 24 + j for j in range(3)])
                            rows.extend([row] * 9)
                            cols.extend(range(x0 + 9 * m, x0 + 9 * m + 9))
                        elif kind == "dyn_g":
                            add(row, [base + 12 + 3 * i + j for j in range(3)] + [base + 21 + i])
                            rows.extend([row] * 3)
                            cols.extend(range(x0 + 9 * m, x0 + 9 * m + 3))
                        elif kind == "st_a":
                            add(row, [base + 3 * i + j for j in range(3)] + [base + 9 + i])
                            rows.extend([row] * 2)
                            cols.extend([ang0 + 2 * m, ang0 + 2 * m + 1])
                        else:
                            add(row, [base + 21 + i])
                        row += 1
        return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(row, self.z0.size))


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: array_full_scipy.py FILE (from array_full_ceres_bench export N FILE)")
    p = load(sys.argv[1])
    model = Model(p)
    sparsity = model.sparsity()  # the problem's structure, not timed (as Ceres' is not)
    cost0 = float(np.sum(model.residuals(model.z0) ** 2))
    cpu0, wall0 = time.process_time(), time.perf_counter()
    res = least_squares(model.residuals, model.z0, jac_sparsity=sparsity, x_scale="jac",
                        ftol=1e-10, xtol=1e-10, gtol=1e-14, max_nfev=10000)
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"scipy  dynamic={p['Nd']} statics={p['J']} unknowns={model.z0.size} "
          f"residuals={sparsity.shape[0]} iterations={res.nfev} njev={res.njev} "
          f"cost={2 * res.cost:.10g} start_cost={cost0:.10g} wall_s={wall:.3f} cpu_s={cpu:.3f} "
          f"max_rss_MB={rss:.1f} status={res.status} ({res.message})")


if __name__ == "__main__":
    main()
