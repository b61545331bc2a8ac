"""UserError: one line naming the file and the key, whatever the message quotes."""

from relray.core.errors import UserError, one_line


def test_message_names_file_and_key():
    assert str(UserError("must be > 0", key="objects[0].radius", file="job.toml")) == \
        "job.toml: key 'objects[0].radius': must be > 0"
    assert str(UserError("bad")) == "bad"


def test_control_characters_are_escaped_into_one_line():
    """A value or file name with a newline (a fuzzed glTF field, a hostile path) cannot
    break the one-line contract."""
    e = UserError("got '\n'\x00", key="k", file="dir\nname.toml")
    assert "\n" not in str(e) and "\x00" not in str(e)
    assert str(e) == "dir\\nname.toml: key 'k': got '\\n'\\x00"
    assert one_line("é ok") == "é ok"


def test_c1_controls_and_unicode_line_breaks_are_escaped():
    """NEL (U+0085) and the line and paragraph separators split lines too (terminals,
    ``str.splitlines``): a template or file name carrying one stays on one line."""
    text = one_line("a\x85b\u2028c\u2029d\x9be")
    assert len(text.splitlines()) == 1 and text.isprintable()
    assert text == "a\\x85b\\u2028c\\u2029d\\x9be"
