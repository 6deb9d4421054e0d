"""
Run every package's tests with colcon, then the cross-package tests in test/, and summarise.

Fails when anything fails, and also when a package ran no test at all: a green run that tested
nothing is a failure here (an ament_python package without pytest declared runs 0 tests).
"""
import pathlib
import subprocess
import sys
import xml.etree.ElementTree as ET

TOP = pathlib.Path(__file__).resolve().parent.parent


def junit_counts(path):
    """Return (tests, failures, skipped) summed over the testsuites of one JUnit XML file."""
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == 'testsuite' else root.findall('testsuite')
    tests = sum(int(s.get('tests', 0)) for s in suites)
    failed = sum(int(s.get('failures', 0)) + int(s.get('errors', 0)) for s in suites)
    skipped = sum(int(s.get('skipped', 0)) for s in suites)
    return tests, failed, skipped


def packages():
    """
    List the packages with code of their own.

    Interface-only packages are tested in test/test_interfaces.py.
    """
    return sorted(p.parent.name for p in (TOP / 'src').glob('*/package.xml')
                  if not (p.parent / 'msg').is_dir())


def has_code(pkg):
    """
    Return True when the package has a Python module beyond its __init__.py.

    Then it must have tests.
    """
    return any(f.name != '__init__.py' for f in (TOP / 'src' / pkg / pkg).glob('*.py'))


def main():
    results = TOP / 'build' / 'test-results'
    colcon = subprocess.run(
        ['colcon', 'test', '--event-handlers', 'console_direct+',
         '--pytest-args', '-p', 'no:cacheprovider', '-q'], cwd=TOP)
    rows = []
    empty_skeletons = [pkg for pkg in packages() if not has_code(pkg)]
    for pkg in packages():
        if pkg in empty_skeletons:
            continue
        xml = TOP / 'build' / pkg / 'pytest.xml'
        if not xml.exists():
            xml = (next(iter((TOP / 'build' / pkg / 'test_results').rglob('*.xml')), None)
                   if (TOP / 'build' / pkg / 'test_results').exists() else None)
        rows.append((pkg, *(junit_counts(xml) if xml else (0, 0, 0))))
    results.mkdir(parents=True, exist_ok=True)
    system_xml = results / 'system.xml'
    system = subprocess.run(
        [sys.executable, '-m', 'pytest', '-p', 'no:cacheprovider', '-q', str(TOP / 'test'),
         f'--junitxml={system_xml}'], cwd=TOP)
    rows.append(('test/ (system)',
                 *(junit_counts(system_xml) if system_xml.exists() else (0, 0, 0))))

    print('\n%-26s %6s %6s %6s' % ('suite', 'tests', 'failed', 'skipped'))
    for name, tests, failed, skipped in rows:
        print('%-26s %6d %6d %6d%s' % (name, tests, failed, skipped,
                                       '   <- ran no test' if tests == 0 else ''))
    total = sum(r[1] for r in rows)
    failed = sum(r[2] for r in rows)
    skipped = sum(r[3] for r in rows)
    empty = [r[0] for r in rows if r[1] == 0]
    for pkg in empty_skeletons:
        print('%-26s   (no code yet: nothing to test)' % pkg)
    print(f'summary: {total - failed - skipped} passed, {failed} failed, {skipped} skipped')
    if colcon.returncode or system.returncode or failed or empty:
        if empty:
            print('FAILED: no test ran in ' + ', '.join(empty))
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
