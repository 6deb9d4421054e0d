"""
Which parameters the measurements determine: QR with column pivoting of the observation matrix.

The whitened observation matrix (identification.whitened_problem) is scaled by parameter units --
1 mm for lengths, 1 mrad for angles (1 mrad turns the 1 m forearm by about 1 mm) -- so that its
columns compare what a unit error of each parameter does to the constraints. Then:

* rank: QR with column pivoting orders the parameters by how much each adds to what the previous
  ones explain; |R_jj| below ``rtol`` times |R_11| means parameter j adds nothing (structurally
  unidentifiable). The null space, put in reduced row-echelon form, names the combinations the
  data cannot see (e.g. a change of H_i equal to a change of h_i: only H_i - h_i enters eq. 4).
* weak: a parameter whose unit change moves the constraints less than a third as much as the
  median parameter's (its scaled column norm) is reported weak -- identifiable in principle but,
  like phi_i, the first to be swamped by noise and model error. The Cramer-Rao standard deviation
  says by how much.
"""
from dataclasses import dataclass

import numpy as np
from robotenis_kinematics import identification
import scipy.linalg

WEAK_FRACTION = 1.0 / 3.0


def unit_scales(names):
    """Scale of each parameter: 1e-3 m for lengths, 1e-3 rad for angles."""
    return np.full(len(names), 1e-3)


def is_angle(name):
    """Return True for angle parameters (phi_i, theta_i0), whose unit is rad."""
    return name.startswith(('phi', 'theta'))


@dataclass
class Observability:
    """Result of the observability analysis."""

    names: tuple
    pivot_order: tuple          # parameter names in QR pivot order
    r_diag: np.ndarray          # |R_jj| / |R_11| in pivot order
    rank: int
    unidentifiable: tuple       # parameters dropped (beyond the rank), in pivot order
    combinations: list          # [{name: coefficient}] basis of the null space (directions unseen)
    sensitivity: dict           # scaled column norm relative to the median, per parameter
    weak: tuple
    std: dict                   # Cramer-Rao standard deviation of the identifiable parameters (SI)

    @property
    def identifiable(self):
        return tuple(n for n in self.names if n not in self.unidentifiable)


def _null_basis(Js, rtol):
    """Reduced row-echelon basis (m, p) of the numerical null space of Js."""
    _, s, Vt = np.linalg.svd(Js, full_matrices=True)
    s = np.concatenate([s, np.zeros(Vt.shape[0] - len(s))])
    N = Vt[s <= rtol * s[0]]
    if len(N) == 0:
        return N
    rows = []
    A = N.copy()
    for col in range(A.shape[1]):
        if len(rows) == len(A):
            break
        candidates = np.arange(len(rows), len(A))
        k = candidates[np.argmax(np.abs(A[candidates, col]))]
        if abs(A[k, col]) < 1e-8:
            continue
        A[[len(rows), k]] = A[[k, len(rows)]]
        A[len(rows)] /= A[len(rows), col]
        for j in range(len(A)):
            if j != len(rows):
                A[j] -= A[j, col] * A[len(rows)]
        rows.append(col)
    A[np.abs(A) < 1e-8] = 0.0
    return A[:len(rows)]


def analyse(model, meas, names=identification.ALL_PARAMETERS, rtol=1e-9):
    """Observability of ``names`` for the poses in ``meas`` at ``model`` (see module docstring)."""
    names = tuple(names)
    _, J_w = identification.whitened_problem(model, meas, names)
    Js = J_w * unit_scales(names)
    _, R, piv = scipy.linalg.qr(Js, mode='economic', pivoting=True)
    r = np.abs(np.diag(R)) / abs(R[0, 0])
    rank = int(np.sum(r > rtol))
    dropped = tuple(names[j] for j in piv[rank:])
    combos = [{names[j]: float(v) for j, v in enumerate(row) if v != 0.0}
              for row in _null_basis(Js, rtol)]
    norms = np.linalg.norm(Js, axis=0)
    rel = norms / np.median(norms)
    sensitivity = dict(zip(names, rel))
    keep = [n for n in names if n not in dropped]
    weak = tuple(n for n in keep if sensitivity[n] < WEAK_FRACTION)
    J_keep = J_w[:, [names.index(n) for n in keep]]
    cov = np.linalg.inv(J_keep.T @ J_keep)
    std = dict(zip(keep, np.sqrt(np.diag(cov))))
    return Observability(names, tuple(names[j] for j in piv), r, rank, dropped, combos,
                         sensitivity, weak, std)


def describe_combination(combo):
    """Describe one unseen direction: for two parameters moving together, the combination seen."""
    if len(combo) == 2:
        (n1, c1), (n2, c2) = combo.items()
        sign = '-' if c1 * c2 > 0 else '+'
        return f'{n1} and {n2} enter only as {n2} {sign} {n1}'
    return 'no data constrain ' + ' + '.join(f'{c:.3g} {n}' for n, c in combo.items())


def format_report(obs):
    """Return a human-readable report of the analysis (mm and mrad)."""
    lines = [f'Observability of {len(obs.names)} parameters: rank {obs.rank} '
             f'(QR with column pivoting, units 1 mm / 1 mrad)']
    for combo in obs.combinations:
        lines.append('  unidentifiable: ' + describe_combination(combo))
    lines.append(f'  weak (sensitivity < {WEAK_FRACTION:.2f} of the median): '
                 + (', '.join(obs.weak) or 'none'))
    lines.append('  %-8s %12s %14s' % ('param', 'sensitivity', 'CRB std'))
    for n in obs.names:
        unit, k = ('mrad', 1e3) if is_angle(n) else ('mm', 1e3)
        std = f'{obs.std[n] * k:9.4f} {unit}' if n in obs.std else '   (dropped)'
        lines.append('  %-8s %12.2f %14s' % (n, obs.sensitivity[n], std))
    return '\n'.join(lines)
