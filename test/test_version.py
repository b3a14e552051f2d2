"""One version, written in package.xml: setup.py, the package and the command line agree."""

import importlib.metadata
import json
from pathlib import Path
import re
import subprocess
import sys
import xml.etree.ElementTree as ET

import pytest

import threat_planner
from threat_planner import _version

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).with_name('threat-planner')
CHANGELOG = ROOT / 'CHANGELOG.md'
#: A release's heading: version, then its tag's date or, until the tag is made, Unreleased.
RELEASE = re.compile(r'^## (\d+\.\d+\.\d+) - (Unreleased|\d{4}-\d{2}-\d{2})$', re.M)


def manifest_version() -> str:
    return ET.parse(ROOT / 'package.xml').getroot().findtext('version').strip()


def test_setup_py_the_package_and_the_command_line_say_package_xml_s_version():
    setup_py = subprocess.run([sys.executable, 'setup.py', '--version'], cwd=ROOT,
                              capture_output=True, text=True, timeout=120)
    assert setup_py.returncode == 0, setup_py.stderr
    if not SCRIPT.exists():
        pytest.skip(f'no threat-planner script beside {sys.executable}')
    cli = subprocess.run([str(SCRIPT), '--version'], capture_output=True, text=True,
                         timeout=120)
    assert cli.returncode == 0, cli.stderr
    version = manifest_version()
    assert setup_py.stdout.strip().splitlines()[-1] == version
    assert cli.stdout.strip() == f'threat-planner {version}'
    assert threat_planner.__version__ == version


def test_the_version_is_a_release_number():
    """major.minor.patch, as bloom and PEP 440 both read it."""
    assert [part.isdigit() for part in manifest_version().split('.')] == [True] * 3


def test_importing_the_package_reads_no_version_until_asked():
    """``import threat_planner`` stays cheap: no XML parser, no metadata lookup."""
    probe = ('import json, sys\n'
             'before = set(sys.modules)\n'
             'import threat_planner\n'
             'loaded = set(sys.modules) - before\n'
             'print(json.dumps(sorted(m for m in loaded if m.startswith(('
             '"xml", "importlib.metadata", "threat_planner._version")))))\n')
    p = subprocess.run([sys.executable, '-c', probe], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert json.loads(p.stdout) == []


def test_a_checkout_reads_its_package_xml_before_the_installed_metadata(monkeypatch, tmp_path):
    """An editable install's metadata keeps the version of its last ``pip install -e``."""
    monkeypatch.setattr(_version, 'CHECKOUT_PACKAGE_XML', ROOT / 'package.xml')
    assert _version.version() == manifest_version()
    monkeypatch.setattr(_version, 'CHECKOUT_PACKAGE_XML', tmp_path / 'package.xml')
    try:
        installed = importlib.metadata.version('threat_planner')
    except importlib.metadata.PackageNotFoundError:
        installed = '0+unknown'
    assert _version.version() == installed


@pytest.mark.parametrize('text', [
    '<package format="3"><name>other_package</name><version>9.9.9</version></package>',
    '<package format="3"><name>threat_planner</name></package>',
    '<package format="3"><name>threat_planner</name><version>',
    'not xml at all',
])
def test_a_manifest_that_is_not_ours_or_is_broken_gives_no_version(tmp_path, text):
    (tmp_path / 'package.xml').write_text(text)
    assert _version.package_xml_version(tmp_path / 'package.xml') is None
    assert _version.package_xml_version(tmp_path / 'missing.xml') is None


def releases() -> list[tuple[str, str]]:
    return RELEASE.findall(CHANGELOG.read_text())


def test_the_changelog_s_newest_release_is_the_package_s_version():
    (newest, _), *_ = releases()
    assert newest == manifest_version() == threat_planner.__version__


def test_the_changelog_lists_releases_newest_first_and_only_the_newest_unreleased():
    found = releases()
    versions = [tuple(map(int, v.split('.'))) for v, _ in found]
    assert versions == sorted(set(versions), reverse=True)
    assert 'Unreleased' not in [date for _, date in found[1:]]
    # Every second-level heading is a release's: one misspelt would escape the checks.
    headings = [line for line in CHANGELOG.read_text().splitlines() if line.startswith('## ')]
    assert len(headings) == len(found), headings


def test_a_tagged_release_is_dated_as_its_tag_and_an_untagged_one_is_unreleased():
    """Tagging v<version> without dating its heading fails here (no tags: nothing to check)."""
    for version, date in releases():
        p = subprocess.run(['git', 'log', '-1', '--format=%cs', f'v{version}^{{commit}}'],
                           cwd=ROOT, capture_output=True, text=True)
        tagged = p.returncode == 0
        if date == 'Unreleased':
            assert not tagged, f'v{version} is tagged: date its heading in CHANGELOG.md'
        elif tagged:
            assert p.stdout.strip() == date, f'v{version} was tagged on {p.stdout.strip()}'
