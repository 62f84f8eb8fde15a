"""A griffe extension for the documentation site: contactlab's docstrings are prose written for
``help()`` and editors, with Sphinx roles (:func:`contactlab.lcp.solve_lcp`) and reST literal
blocks ("record::" before an indented example). Markdown knows neither, so at build time each
role becomes a cross-reference to the object's page when the site documents it (plain code
otherwise), and "::" ending a paragraph becomes ":". The sources are left as they are.
(Dataclass fields and constants carry attribute docstrings, the string on the line after them,
which griffe reads itself.)
"""

import re

import griffe

ROLE = re.compile(r":(?:func|meth|class|mod|data|attr|obj|exc):`(~?)([\w.]+?)(\(\))?`")
LITERAL = re.compile(r"(\S)::$", re.MULTILINE)


class ProseDocstrings(griffe.Extension):
    def on_package(self, *, pkg, loader, **kwargs):
        self.loader = loader
        self._walk(pkg)

    def _walk(self, obj):
        if obj.docstring is not None:
            obj.docstring.value = self._rewrite(obj, obj.docstring.value)
        for member in obj.members.values():
            if not member.is_alias:
                self._walk(member)

    def _rewrite(self, obj, text):
        def link(match):
            short, target, call = match.groups()
            path = self._resolve(obj, target)
            shown = (target.rsplit(".", 1)[-1] if short else target) + (call or "")
            # optional: a target the site does not document renders as plain code, no warning
            return f'<autoref identifier="{path}" optional><code>{shown}</code></autoref>'

        return LITERAL.sub(r"\1:", ROLE.sub(link, text))

    def _resolve(self, obj, target):
        """The full path of ``target`` as written in ``obj``'s docstring: absolute, or relative
        to the object's class or module, or to the contactlab package."""
        module = obj if obj.is_module else obj.module
        scopes = ["", f"{obj.path}.", f"{obj.parent.path}." if obj.parent else "", f"{module.path}.",
                  "contactlab."]
        for scope in scopes:
            try:
                found = self.loader.modules_collection[scope + target]
            except (KeyError, ValueError, griffe.AliasResolutionError, griffe.CyclicAliasError):
                continue
            try:
                return found.final_target.path if found.is_alias else found.path
            except (griffe.AliasResolutionError, griffe.CyclicAliasError):
                return found.path
        return target

