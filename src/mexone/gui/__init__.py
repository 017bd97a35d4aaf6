"""The web GUI (`mexone sim`'s page, viser): the frame loop and every panel of the page."""
