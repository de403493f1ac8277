"""OpenCV image lists that are not what they claim (issue 48): nested 100,000 deep, binary, an XML entity, a
200,000-entry list (it took over a minute: OpenCV's FileNode walks to item k; now refused by its count before
any item is read). Each is one FileFormatError naming the file, never an internal error."""

from __future__ import annotations

import pytest

from rangekit.errors import FileFormatError
from rangekit.formats.layouts.opencv import MAX_LIST_ENTRIES, read_image_list

CASES = {
    "deep.yaml": ("%YAML:1.0\n---\ncam1: " + "[" * 100_000 + "]" * 100_000 + "\n", "cannot parse"),
    "deep.xml": ('<?xml version="1.0"?>\n<opencv_storage>\n' + "<a>" * 100_000 + "</a>" * 100_000
                 + "</opencv_storage>\n", "cannot parse"),
    "binary.yaml": (bytes(range(256)) * 100, "found binary data"),
    "entity.xml": ('<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e "aaaa">]>\n<opencv_storage><cam1>"&e;"</cam1>'
                   "</opencv_storage>\n", "document type or entity"),
    "long.yaml": ("%YAML:1.0\n---\ncam1:\n" + "".join(f'   - "f{i}.png"\n' for i in range(200_000)),
                  f"expected at most {MAX_LIST_ENTRIES} frames a camera, found 200000"),
    "numbers.yaml": ("%YAML:1.0\n---\ncam1: [1, 2, 3]\n", "to list file names"),
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_bad_image_list_is_one_clear_error(tmp_path, name):
    content, mention = CASES[name]
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(FileFormatError) as refused:
        read_image_list(path)
    assert str(path) in str(refused.value) and mention in str(refused.value), refused.value
    assert "internal" not in str(refused.value) and len(str(refused.value)) < 400
