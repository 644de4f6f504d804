//! Table-driven CRCs shared by the wire protocol (serial frames, CAN end-to-end protection) and the model files.
//!
//! Tables are built at compile time; each function costs one table lookup per byte and no allocation. The check
//! values in the tests are the catalogue values for the ASCII string `123456789` (reveng CRC catalogue).

/// CRC-32C (Castagnoli): reflected polynomial 0x1EDC6F41, init and xorout 0xFFFFFFFF, check 0xE3069283.
pub fn crc32c(data: &[u8]) -> u32 {
    crc32c_update(0xFFFF_FFFF, data) ^ 0xFFFF_FFFF
}

/// Continue a CRC-32C over more bytes: start from `0xFFFF_FFFF`, xor the result with `0xFFFF_FFFF` at the end.
pub fn crc32c_update(mut state: u32, data: &[u8]) -> u32 {
    for &b in data {
        state = CRC32C_TABLE[((state ^ b as u32) & 0xFF) as usize] ^ (state >> 8);
    }
    state
}

/// CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740): polynomial 0x1021, init 0xFFFF, not reflected, check 0x29B1.
pub fn crc16_ccitt(data: &[u8]) -> u16 {
    let mut state: u16 = 0xFFFF;
    for &b in data {
        state = CRC16_TABLE[((state >> 8) as u8 ^ b) as usize] ^ (state << 8);
    }
    state
}

/// CRC-8/SAE-J1850 as used by AUTOSAR E2E profile 1: polynomial 0x1D, init 0xFF, xorout 0xFF, check 0x4B.
pub fn crc8_sae_j1850(data: &[u8]) -> u8 {
    crc8_sae_j1850_update(0xFF, data) ^ 0xFF
}

/// Continue a CRC-8/SAE-J1850 over more bytes: start from `0xFF`, xor the result with `0xFF` at the end.
pub fn crc8_sae_j1850_update(mut state: u8, data: &[u8]) -> u8 {
    for &b in data {
        state = CRC8_TABLE[(state ^ b) as usize];
    }
    state
}

static CRC32C_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0x82F6_3B78 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

static CRC16_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u16) << 8;
        let mut k = 0;
        while k < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

static CRC8_TABLE: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u8;
        let mut k = 0;
        while k < 8 {
            c = if c & 0x80 != 0 { (c << 1) ^ 0x1D } else { c << 1 };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

#[cfg(test)]
mod tests {
    use super::*;

    const CHECK: &[u8] = b"123456789";

    #[test]
    fn catalogue_check_values() {
        assert_eq!(crc32c(CHECK), 0xE306_9283);
        assert_eq!(crc16_ccitt(CHECK), 0x29B1);
        assert_eq!(crc8_sae_j1850(CHECK), 0x4B);
    }

    #[test]
    fn empty_input_gives_init_xor_out() {
        assert_eq!(crc32c(&[]), 0);
        assert_eq!(crc16_ccitt(&[]), 0xFFFF);
        assert_eq!(crc8_sae_j1850(&[]), 0x00);
    }

    #[test]
    fn incremental_equals_one_shot() {
        let s = crc32c_update(0xFFFF_FFFF, &CHECK[..4]);
        assert_eq!(crc32c_update(s, &CHECK[4..]) ^ 0xFFFF_FFFF, crc32c(CHECK));
        let s = crc8_sae_j1850_update(0xFF, &CHECK[..3]);
        assert_eq!(
            crc8_sae_j1850_update(s, &CHECK[3..]) ^ 0xFF,
            crc8_sae_j1850(CHECK)
        );
    }
}
