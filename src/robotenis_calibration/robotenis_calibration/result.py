"""
RESULT.yaml: the calibrated robot description, the effects found, and the report.

Same schema as every robot description (robotenis_kinematics.description), plus ``effects``
(each with its parameters and their standard deviations) and ``report`` (the residual loop's
numbers), so ``./robotenis fk --model RESULT.yaml`` and the motion controller can use it directly.
"""
import numpy as np

from robotenis_calibration import diagnosis as dg
from robotenis_kinematics import effects as fx
from robotenis_kinematics import identification as idf
from robotenis_kinematics.identification import LEG_PARAMETERS


def _std(result, name):
    return float(result.std[result.names.index(name)]) if name in result.names else None


def calibrated_description(diagnosis, declared):
    """Return the declared description with the final geometry, camera rotation and effects."""
    final = diagnosis.final
    desc = final.model.desc.copy(effects=[], report={})
    if 'hand_eye_rotation' in final.model.effects:
        turn = fx.rotation_vector_matrix(final.model.effects['hand_eye_rotation'])
        desc.camera_rotation = turn @ declared.camera_rotation
    for name in diagnosis.effects:
        entry = {'name': name}
        if name in dg.GENERIC:
            entry.update(_generic_entry(diagnosis, name))
        elif name == 'base_geometry':
            for key in fx.BASE_GEOMETRY_KEYS:
                names = [f'{key}{i}' for i in (1, 2, 3) if f'{key}{i}' in final.names]
                if names:
                    entry[key] = [float(v) for v in getattr(desc, key)]
                    entry[key + '_std'] = [_std(final, f'{key}{i}') or 0.0 for i in (1, 2, 3)]
        else:
            key = fx.PARAMETERS[name][0]
            entry[key] = [float(v) for v in final.model.effects[name]]
            entry[key + '_std'] = [_std(final, f'{name}{i}') or 0.0 for i in (1, 2, 3)]
            if name == 'gravity_compliance':
                entry['gravity_load'] = dict(fx.NOMINAL_GRAVITY_LOAD)
        desc.effects.append(entry)
    desc.report = report(diagnosis)
    return desc


def _generic_entry(diagnosis, name):
    """Return the YAML entry of a generic effect: its terms, their standard deviations, meaning."""
    final, size = diagnosis.final, diagnosis.sizes.get(name)
    prefix = 'joint_' if name == 'joint_harmonics' else 'camera_'
    terms = {t: v for t, v in final.model.effects.items()
             if t.startswith(prefix) and fx.is_effect(t) and t not in fx.PARAMETERS}
    entry = {'terms': {t[len(prefix):]: [float(x) for x in v] for t, v in terms.items()},
             'terms_std': {t[len(prefix):]: [_std(final, f'{t}{i}') or 0.0 for i in (1, 2, 3)]
                           for t in terms}}
    if name == 'joint_harmonics':
        entry['kind'] = ('an error of each arm angle periodic in that angle, orders '
                         + ', '.join(str(n) for n in size))
    else:
        entry['reference_range'] = fx.CAMERA_REFERENCE_RANGE
        entry['kind'] = ('an error of the camera measurement along its optical axes, a '
                         'polynomial in x/z_ref, y/z_ref, z/z_ref - 1 with the coefficients '
                         + ', '.join(n[len(prefix):] for n in size))
    entry['correlates'] = [{'feature': f, 'component': c, 'r': round(r, 3)}
                           for f, c, r in diagnosis.correlates.get(name, [])]
    return entry


def _parameters(result):
    rows = {}
    for name, value, std in zip(result.names, result.U, result.std):
        rows[name] = {'value': float(value), 'std': float(std)}
    return rows


def report(diagnosis):
    """Return the numbers of the residual loop as plain data (SI units; errors in mm as named)."""
    steps = []
    for step in diagnosis.steps:
        steps.append({
            'candidates': [{'name': t.name, 'statistic': t.statistic, 'dof': t.dof,
                            'p_value': t.p_value, 'parameters': list(t.parameters),
                            'unidentifiable': list(t.dropped)}
                           for t in step.tests],
            'chosen': step.chosen, 'kept': step.kept, 'reason': step.reason,
            'chi2_before': step.chi2_before, 'chi2_after': step.chi2_after,
            'likelihood_ratio_p': step.lr_p_value, 'holdout_p': step.holdout_p_value,
            'generic_adds_p': step.generic_p_value,
            'equivalent': [{'name': n, 'adds_p': a, 'gains_p': g} for n, a, g in step.equivalent],
        })
    rms, largest, poses = diagnosis.workspace_fk_std_mm
    return {
        'poses': {'train': int(len(diagnosis.train)), 'holdout': int(len(diagnosis.holdout))},
        'holdout_rms_error_mm': dict(diagnosis.errors_mm),
        'workspace_fk_std_mm': {'rms': rms, 'largest': largest, 'poses': poses},
        'holdout_chi2': dict(diagnosis.holdout_chi2),
        'holdout_test': dict(diagnosis.size_test),
        'noise_floor': diagnosis.floor.as_dict() if diagnosis.floor else None,
        'generic_sizes': {k: (list(v) if isinstance(v, tuple) else v)
                          for k, v in diagnosis.sizes.items()},
        'effects_found': list(diagnosis.effects),
        'indistinguishable': diagnosis.indistinguishable,
        'steps': steps,
        'unexplained_structure': [{'feature': f, 'joint': j, 'correlation': r, 'p_value': p}
                                  for f, j, r, p in diagnosis.fallback],
        'parameters_plain': _parameters(diagnosis.plain),
        'parameters_final': _parameters(diagnosis.final),
        'leg_parameters': list(LEG_PARAMETERS),
    }


def effects_text(diagnosis):
    """Return the effects found for a human, each with those these poses cannot tell from it."""
    alike = diagnosis.indistinguishable
    return ', '.join(name + (f" (or {', '.join(alike[name])}: these poses cannot tell them apart)"
                             if name in alike else '')
                     for name in diagnosis.effects) or 'none'


def summary(diagnosis):
    """Return lines for a human: before/after errors, effects, flags."""
    e = diagnosis.errors_mm
    lines = [f"held-out RMS error: nominal {e['nominal']:.3f} mm,"
             f" plain 15-parameter {e['plain']:.3f} mm, "
             f"final {e['final']:.3f} mm ({len(diagnosis.holdout)} held-out poses)",
             f'effects found: {effects_text(diagnosis)}']
    for name, correlates in diagnosis.correlates.items():
        size = diagnosis.sizes[name]
        size = f"orders {', '.join(map(str, size))}" if name == 'joint_harmonics' else \
            f"coefficients {', '.join(n[len('camera_'):] for n in size)}"
        found = ', '.join(f'{f} ({c}, r = {r:.2f})' for f, c, r in correlates)
        lines.append(f'  {name} (generic, {size}) correlates with: {found}')
    for step in diagnosis.steps:
        tests = ', '.join(f'{t.name} {t.statistic:.1f}/{t.dof} (p={t.p_value:.2g})'
                          for t in step.tests)
        lines.append(f'  score tests: {tests}')
        lines.append(f'    -> {step.chosen}: {step.reason}')
    rms, largest, poses = diagnosis.workspace_fk_std_mm
    lost = ('' if poses == dg.WORKSPACE_POSES else f' of {dg.WORKSPACE_POSES}; the model cannot '
            'assemble the robot at the others')
    lines.append(f'FK standard deviation over the workspace, from the fit: {rms:.3f} mm RMS, '
                 f'{largest:.3f} mm at most ({poses} boundary poses{lost})')
    size = diagnosis.size_test
    lines.append(f"held-out poses: chi2 {size['chi2']:.1f} for {size['dof']} dof"
                 f" (p = {size['p_value']:.3g}) under the final model and the rests' floor")
    if diagnosis.floor is not None:
        floor = ', '.join(_floor_text(name, value)
                          for name, value in diagnosis.floor.variances.items() if value > 0)
        lines.append(f"rests' error floor (REML): {floor or 'none beyond the frames'}")
    for f, j, r, p in diagnosis.fallback:
        lines.append(f'  UNEXPLAINED: joint {j} residual correlates with {f}'
                     f' (r = {r:.2f}, p = {p:.2g})')
    return lines


def _floor_text(name, variance):
    """Return a floor component as a standard deviation for a human (mm, mrad)."""
    unit, scale = ('mrad', 1e3) if name == 'resolver' else ('mm', 1e3)
    return f'{name} {np.sqrt(variance) * scale:.4f} {unit}'


def plot_residuals(diagnosis, meas, sphere, stamps, path):
    """Plot the final model's whitened residuals against what they could correlate with (PNG)."""
    from matplotlib.figure import Figure    # no pyplot: no GUI backend, nothing global to close
    from matplotlib.ticker import MaxNLocator

    feats = dg.residual_features(diagnosis.final.model, meas, sphere, stamps)
    shown = ('joint angle', 'motion direction', 'gravity torque', 'image x', 'image y', 'time')
    plain = idf.whitened_problem(diagnosis.plain.model, meas, ())[0].reshape(-1, 3)
    final = idf.whitened_problem(diagnosis.final.model, meas, ())[0].reshape(-1, 3)
    fig = Figure(figsize=(4 * len(shown), 6.5))
    axes = fig.subplots(2, len(shown), sharey='row')
    for col, name in enumerate(shown):
        values = feats[name]
        for row, (label, r) in enumerate((('plain 15-parameter', plain), ('final', final))):
            ax = axes[row, col]
            for leg in range(3):
                x = values[:, leg] if np.ndim(values) == 2 else values
                ax.plot(x, r[:, leg], '.', ms=3, label=f'leg {leg + 1}')
            ax.axhline(0, color='k', lw=0.5)
            ax.set_xlabel(name)
            # few ticks: each is five artists, and drawing them was most of the plot's time
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.yaxis.set_major_locator(MaxNLocator(5))
            if col == 0:
                ax.set_ylabel(f'{label}\nwhitened residual')
    axes[0, 0].legend(fontsize=7)
    fig.suptitle('Residuals against what they may correlate with'
                 ' (whitened: unit variance if the model is right)')
    # fixed margins: tight_layout would measure every label, most of the plot's time
    fig.subplots_adjust(left=0.05, right=0.99, bottom=0.09, top=0.92, wspace=0.12, hspace=0.3)
    fig.savefig(path, dpi=80, format='png')
