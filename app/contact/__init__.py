"""Contacts at points, for every tier that evaluates them there: where a contact acts on a surface (its
sites: sampling and interface choice, app/contact/sites.py), the law at a site compiled (app/contact/law.py)
and its records built from a case (app/contact/records.py)."""
