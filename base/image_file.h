// Cheap checks on an image file's bytes before a decoder sees them: libjpeg and libpng decode a
// truncated file with only a warning on stderr (and grey or black rows where the data stopped), so
// a cut-off download would be searched as if it were the whole image.
#pragma once

#include <filesystem>

#include "base/status.h"

namespace handdb {

// A regular file (CheckRegularFile) and, for a JPEG (FF D8 FF) or PNG (89 'PNG' ...) by content,
// complete: the JPEG's end-of-image marker (FF D9) or the PNG's IEND chunk is within its last
// 4 KiB (decoders allow trailing bytes). Other formats pass unchecked.
// kBadImage "<file>: truncated JPEG (no end-of-image marker)" / "... PNG (no IEND chunk)".
Status CheckImageFileComplete(const std::filesystem::path& path);

}  // namespace handdb
