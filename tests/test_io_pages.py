"""Page-writing helpers of `jaxdeploy.io`: generated blocks and the commit a page records."""

from jaxdeploy.io import machine_description, replace_block, revision_label


def test_replace_block_keeps_the_prose_around_it(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\nprose\n<!-- BEGIN t -->\nold\n<!-- END t -->\nmore prose\n")
    replace_block(str(page), "t", "new 1\nnew 2\n")
    assert page.read_text() == (
        "# Title\n\nprose\n<!-- BEGIN t -->\nnew 1\nnew 2\n<!-- END t -->\nmore prose\n"
    )
    replace_block(str(page), "u", "other")  # a block the page lacks is appended
    assert page.read_text().endswith("more prose\n\n<!-- BEGIN u -->\nother\n<!-- END u -->\n")


def test_replace_block_creates_a_missing_page(tmp_path):
    page = tmp_path / "sub" / "new.md"
    replace_block(str(page), "b", "x")
    assert page.read_text() == "\n\n<!-- BEGIN b -->\nx\n<!-- END b -->\n"


def test_revision_label():
    sha = "0123456789abcdef0123456789abcdef01234567"
    assert revision_label({"commit": sha, "dirty": False}) == "commit 0123456789"
    assert revision_label({"commit": sha, "dirty": True}).endswith("(uncommitted changes)")
    assert revision_label({}) == "a copy not in git"


def test_machine_description_records_the_load():
    info = machine_description()
    assert len(info["load_average_1_5_15min"]) == 3
    assert info["python"].count(".") == 2
