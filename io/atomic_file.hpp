// Small text files (summary.json, the XDMF index) written so that a reader never sees half of one and a failure
// loses nothing: PATH.tmp is written, flushed to the disk (fsync) and renamed to PATH; the directory is synced
// after the rename. Not collective.
#pragma once
#include <string>

namespace tissue {

// Throws OutputError (partition/agreement.hpp) naming the file and the system error (ENOSPC, EDQUOT, EIO, a failed
// fsync or rename); PATH.tmp is removed then, and an earlier PATH is left as it was.
void write_file_atomically(const std::string& path, const std::string& contents);

}  // namespace tissue
