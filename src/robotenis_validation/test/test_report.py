import re

from robotenis_sim.scenarios import EFFECTS
from robotenis_validation import report


def test_quick_report_has_every_section_and_its_figures(tmp_path):
    path = report.build(str(tmp_path), quick=True, say=lambda text: None)
    page = open(path).read()
    for title in ('Identification beside', 'The residual loop', 'Choosing the poses',
                  'The Jacobian study', 'Static tests, ISO 9283', 'Tracking (section 6.2.2)'):
        assert title in page
    for image in re.findall(r'<img src="([^"]+)"', page):
        assert (tmp_path / image).stat().st_size > 10_000
    # One row per studied effect, each named in its one session (the study's sizes are chosen so).
    rows = re.findall(r'<tr><td>(\w+)</td><td>(\d+)/(\d+)</td>', page)
    assert {r[0] for r in rows} == set(EFFECTS)
    assert all(r[1] == r[2] for r in rows)
    # The static tests: the calibrated models position better than the nominal one on the plate.
    means = dict(re.findall(r'<tr><td>([\w ()-]+)</td><td>([\d.]+)</td>'
                            r'<td>[\d.]+</td><td>[\d.]+</td><td>[\d.]+</td></tr>', page))
    assert (float(means['final (residual loop)']) < float(means['plain 15-parameter'])
            < float(means['nominal']))
    # and so do the models calibrated through rendered images, as the live session measures
    through_images = dict(re.findall(r'<tr><td>(\w+), through images</td><td>([\d.]+)</td>', page))
    assert set(through_images) == {'plain', 'final'}
    assert max(map(float, through_images.values())) < float(means['nominal'])
