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
        if name == 'base_geometry':
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
        })
    return {
        'poses': {'train': int(len(diagnosis.train)), 'holdout': int(len(diagnosis.holdout))},
        'holdout_rms_error_mm': dict(diagnosis.errors_mm),
        'holdout_chi2': dict(diagnosis.holdout_chi2),
        'residual_size_test': dict(diagnosis.size_test),
        'effects_found': list(diagnosis.effects),
        'steps': steps,
        'unexplained_structure': [{'feature': f, 'joint': j, 'correlation': r, 'p_value': p}
                                  for f, j, r, p in diagnosis.fallback],
        'parameters_plain': _parameters(diagnosis.plain),
        'parameters_final': _parameters(diagnosis.final),
        'leg_parameters': list(LEG_PARAMETERS),
    }


def summary(diagnosis):
    """Return lines for a human: before/after errors, effects, flags."""
    e = diagnosis.errors_mm
    lines = [f"held-out RMS error: nominal {e['nominal']:.3f} mm,"
             f" plain 15-parameter {e['plain']:.3f} mm, "
             f"final {e['final']:.3f} mm ({len(diagnosis.holdout)} held-out poses)",
             f"effects found: {', '.join(diagnosis.effects) or 'none'}"]
    for step in diagnosis.steps:
        tests = ', '.join(f'{t.name} {t.statistic:.1f}/{t.dof} (p={t.p_value:.2g})'
                          for t in step.tests)
        lines.append(f'  score tests: {tests}')
        lines.append(f'    -> {step.chosen}: {step.reason}')
    size = diagnosis.size_test
    lines.append(f"residual size: chi2 {size['chi2']:.1f} for {size['dof']} dof"
                 f" (p = {size['p_value']:.3g})")
    for f, j, r, p in diagnosis.fallback:
        lines.append(f'  UNEXPLAINED: joint {j} residual correlates with {f}'
                     f' (r = {r:.2f}, p = {p:.2g})')
    return lines


def plot_residuals(diagnosis, meas, sphere, stamps, path):
    """Plot the final model's whitened residuals against what they could correlate with (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    feats = dg.residual_features(diagnosis.final.model, meas, sphere, stamps)
    shown = ('joint angle', 'motion direction', 'gravity torque', 'image x', 'image y', 'time')
    plain = idf.whitened_problem(diagnosis.plain.model, meas, ())[0].reshape(-1, 3)
    final = idf.whitened_problem(diagnosis.final.model, meas, ())[0].reshape(-1, 3)
    fig, axes = plt.subplots(2, len(shown), figsize=(4 * len(shown), 6.5), sharey='row')
    for col, name in enumerate(shown):
        values = feats[name]
        for row, (label, r) in enumerate((('plain 15-parameter', plain), ('final', final))):
            ax = axes[row, col]
            for leg in range(3):
                x = values[:, leg] if np.ndim(values) == 2 else values
                ax.plot(x, r[:, leg], '.', ms=3, label=f'leg {leg + 1}')
            ax.axhline(0, color='k', lw=0.5)
            ax.set_xlabel(name)
            if col == 0:
                ax.set_ylabel(f'{label}\nwhitened residual')
    axes[0, 0].legend(fontsize=7)
    fig.suptitle('Residuals against what they may correlate with'
                 ' (whitened: unit variance if the model is right)')
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
