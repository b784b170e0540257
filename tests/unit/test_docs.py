"""The README stays short, and its links and the docs' links lead somewhere."""
import re

from helpers import ROOT

LINK = re.compile(r'\]\(([^)#\s]+)(?:#[^)]*)?\)')


def _relative_links(path):
    return [target for target in LINK.findall(path.read_text())
            if not re.match(r'[a-z]+://|mailto:', target)]


def test_the_readme_is_at_most_250_lines():
    assert len((ROOT / 'README.md').read_text().splitlines()) <= 250


def test_every_relative_link_of_the_readme_and_the_docs_resolves():
    pages = [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]
    broken = [f'{page.relative_to(ROOT)}: {target}' for page in pages
              for target in _relative_links(page)
              if not (page.parent / target).exists()]
    assert _relative_links(ROOT / 'README.md'), 'the README links to nothing'
    assert broken == []


def test_the_readmes_package_table_names_every_package_and_only_those():
    """Each row of the README's package table whose folder holds a package.xml names that
    package; every package of the project has its row."""
    rows = re.findall(r'^\| `([a-z_]+)/` \| `([a-z_]+)` \|', (ROOT / 'README.md').read_text(),
                      re.M)
    packages = {p.parent.name: re.search(r'<name>([^<]+)</name>', p.read_text()).group(1)
                for p in ROOT.glob('*/package.xml')}
    assert dict(rows) == packages


def test_every_module_the_architecture_walk_names_exists():
    """docs/architecture.md walks one material through the project file by file: each file it
    names is a module of the project (a rename that forgets the map fails here)."""
    text = (ROOT / 'docs' / 'architecture.md').read_text()
    named = set(re.findall(r'`(?:[a-z_]+/)*([a-z_]+\.py)`', text))
    packages = [*ROOT.glob('*/package.xml'), *ROOT.glob('ros_ws/src/*/package.xml')]
    modules = {p.name for xml in packages for p in xml.parent.rglob('*.py')}
    modules |= {p.name for p in (ROOT / 'tests').rglob('*.py')}
    assert len(named) >= 12
    assert sorted(named - modules) == []
